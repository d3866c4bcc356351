#version 460
// The fast gather pixel by pixel (fast_gather.glsl).
#include "fast_gather.glsl"
