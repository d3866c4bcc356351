#version 460
// The square splat (splat_raster_frag.glsl).
#include "splat_raster_frag.glsl"
