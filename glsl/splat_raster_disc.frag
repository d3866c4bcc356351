#version 460
// The disc splat (`--splat-shape disc`; splat_raster_frag.glsl).
#define SPLAT_DISC
#include "splat_raster_frag.glsl"
