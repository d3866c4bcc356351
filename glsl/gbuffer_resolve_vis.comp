#version 460
// The compute rasteriser's resolve (gbuffer_resolve_vis.glsl).
#include "gbuffer_resolve_vis.glsl"
