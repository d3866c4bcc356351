#version 460
// The depth peel of square splats (splat_compute_main.glsl).
#define SPLAT_PEEL
#include "splat_compute_main.glsl"
