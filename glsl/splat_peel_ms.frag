#version 460
// The depth peel for multisampled raster passes (splat_peel.glsl): runs
// once per sample and reads the previous layer's same sample.
layout(binding = 0, rgba32f) uniform readonly image2DMS previous; // (r, g, b, z)
#define PREVIOUS_Z imageLoad(previous, ivec2(gl_FragCoord.xy), gl_SampleID).w
#include "splat_peel.glsl"
