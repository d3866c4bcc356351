#version 460
// Square splats (splat_compute_main.glsl).
#include "splat_compute_main.glsl"
