#version 460
// The depth peel of disc splats (`--splat-shape disc`;
// splat_compute_main.glsl).
#define SPLAT_DISC
#define SPLAT_PEEL
#include "splat_compute_main.glsl"
