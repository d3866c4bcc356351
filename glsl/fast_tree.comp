#version 460
// Fast DOF, the block tree (src/passes/fast.rs, glsl/fast_tree.glsl), one
// dispatch per level: the lowest (TREE_LEAF_LEVEL) from the G-buffer's
// pixels (their CoC and weight from fast_coc), each level above from the
// four blocks below.
#include "fast_tree.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D gbuffer_color;
layout(binding = 1, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 2, rg32f) uniform readonly image2D coc_weight;
layout(binding = 3, std430) buffer Sums { vec4 sums[]; };       // Σ w · rgba
layout(binding = 4, std430) buffer Weights { float weights[]; }; // Σ w
layout(binding = 5, std430) buffer Bounds { vec4 bounds[]; };   // z min, z max, c min, c max

layout(push_constant, std430) uniform Push {
    ivec2 extent;   // G-buffer size
    ivec2 padded;   // the extent rounded up to a multiple of 2^levels
    int level;      // the level this dispatch writes, TREE_LEAF_LEVEL to levels
} pc;

// The bounds of two sets of pixels together: (z min, z max, c min, c max).
vec4 merge_bounds(vec4 a, vec4 b) {
    return vec4(min(a.x, b.x), max(a.y, b.y), min(a.z, b.z), max(a.w, b.w));
}

void main() {
    ivec2 b = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(b, tree_level_size(pc.extent, pc.level)))) {
        return;
    }
    vec4 sum = vec4(0.0);
    float weight = 0.0;
    // Background pixels are at z = +inf.
    vec4 bound = vec4(1.0 / 0.0, -1.0 / 0.0, 1.0 / 0.0, -1.0 / 0.0);
    if (pc.level == TREE_LEAF_LEVEL) {
        ivec2 p0 = b << TREE_LEAF_LEVEL;
        ivec2 p1 = min(p0 + (1 << TREE_LEAF_LEVEL), pc.extent);
        for (int y = p0.y; y < p1.y; ++y) {
            for (int x = p0.x; x < p1.x; ++x) {
                ivec2 p = ivec2(x, y);
                vec2 cw = imageLoad(coc_weight, p).xy;
                float z = imageLoad(gbuffer_eye, p).z;
                sum += cw.y * imageLoad(gbuffer_color, p);
                weight += cw.y;
                bound = merge_bounds(bound, vec4(z, z, cw.x, cw.x));
            }
        }
    } else {
        ivec2 below = tree_level_size(pc.extent, pc.level - 1);
        for (int j = 0; j < 2; ++j) {
            for (int i = 0; i < 2; ++i) {
                ivec2 c = 2 * b + ivec2(i, j);
                if (any(greaterThanEqual(c, below))) {
                    continue;
                }
                uint at = tree_index(pc.padded, pc.level - 1, c);
                sum += sums[at];
                weight += weights[at];
                bound = merge_bounds(bound, bounds[at]);
            }
        }
    }
    uint at = tree_index(pc.padded, pc.level, b);
    sums[at] = sum;
    weights[at] = weight;
    bounds[at] = bound;
}
