#version 460
// The depth peel for one-sample raster passes (splat_peel.glsl).
layout(binding = 0, rgba32f) uniform readonly image2D previous; // (r, g, b, z)
#define PREVIOUS_Z imageLoad(previous, ivec2(gl_FragCoord.xy)).w
#include "splat_peel.glsl"
