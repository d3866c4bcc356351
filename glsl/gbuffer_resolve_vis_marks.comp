#version 460
// The compute rasteriser's resolve that marks the pixels that resolve by
// area (gbuffer_resolve_vis.glsl, gbuffer_area.glsl).
#define AREA_MARKS
#include "gbuffer_resolve_vis.glsl"
