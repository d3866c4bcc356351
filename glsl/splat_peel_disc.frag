#version 460
// The disc splat's depth peel (`--splat-shape disc`; splat_peel_frag.glsl).
#define SPLAT_DISC
#include "splat_peel_frag.glsl"
