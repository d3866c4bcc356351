#version 460
// The fast gather over the block tree (fast_gather.glsl, fast_tree.glsl).
#define TREE
#include "fast_gather.glsl"
