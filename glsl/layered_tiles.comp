#version 460
// Layered DOF, pass 1 (DESIGN §6): per TILE×TILE tile of the first layer
// (the surfaces seen through the pinhole), the farthest depth (+inf where a
// pixel sees background) and the largest CoC of a point: what the modified
// peel asks of the occluders near a hidden pixel.
#include "lens.glsl"
#include "layered_push.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform readonly image2D first_eye;
layout(binding = 1, rg32f) uniform writeonly image2D occluder_tiles;

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(t, pc.tiles))) {
        return;
    }
    ivec2 lo = t * pc.tile;
    ivec2 hi = min(lo + pc.tile, pc.extent);
    float z_far = 0.0;
    float c_max = 0.0;
    for (int y = lo.y; y < hi.y; ++y) {
        for (int x = lo.x; x < hi.x; ++x) {
            float z = imageLoad(first_eye, ivec2(x, y)).z;
            z_far = max(z_far, z);
            if (!isinf(z)) {
                c_max = max(c_max, coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance));
            }
        }
    }
    imageStore(occluder_tiles, t, vec4(z_far, c_max, 0.0, 0.0));
}
