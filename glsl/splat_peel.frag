#version 460
// The square splat's depth peel (splat_peel_frag.glsl).
#include "splat_peel_frag.glsl"
