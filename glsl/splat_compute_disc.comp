#version 460
// Disc splats (`--splat-shape disc`; splat_compute_main.glsl).
#define SPLAT_DISC
#include "splat_compute_main.glsl"
