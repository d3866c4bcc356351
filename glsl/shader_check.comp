#version 460
// Evaluates the GLSL includes that mirror CPU formulas (lens.glsl: the thin
// lens of DESIGN §2; concentric.glsl: the concentric map of DESIGN §5;
// aperture.glsl: the cat's eye's blur reach, its pressed lens and an RDB
// bin's weight) on a list of inputs, so that
// tests/shaders.rs can compare them with src/camera. Not used by the
// renderer.
#include "lens.glsl"
#include "concentric.glsl"
#include "aperture.glsl"

layout(local_size_x = 64) in;

// Per case: (z, u.x, u.y, unused), (square point a.x, a.y, disk point u.x, u.y),
// (cat's eye centre x, y, coc.x, coc.y), (shape reach, cat's eye S, behind (0 or 1), |frame/2|).
layout(binding = 0, std430) readonly buffer Inputs { vec4 inputs[]; };
// Per case: (coc_px(z), lens_offset_px(z, u), signed_coc_px(z)),
// (concentric_disk(a), concentric_square(u)), (cat_eye_blur_reach, 0, 0, 0),
// (cat_eye_lens(u, centre), cat_eye_pressed_weight of u pressed into
// centre at a pixel whose circle is centred at 0.9·centre (cells of
// half-width 0.1), cat_lens_area of centre).
layout(binding = 1, std430) writeonly buffer Outputs { vec4 outputs[]; };

layout(push_constant, std430) uniform Push {
    uint count;
    float f_px;
    float aperture_radius;
    float focus_distance;
} pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) {
        return;
    }
    vec4 lens_in = inputs[4 * i];
    vec4 map_in = inputs[4 * i + 1];
    vec4 cat_in = inputs[4 * i + 2];
    vec4 reach_in = inputs[4 * i + 3];
    float z = lens_in.x;
    float c = coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    vec2 offset = lens_offset_px(z, lens_in.yz, pc.f_px, pc.aperture_radius, pc.focus_distance);
    float signed_c = signed_coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    outputs[4 * i] = vec4(c, offset, signed_c);
    outputs[4 * i + 1] = vec4(concentric_disk(map_in.xy), concentric_square(map_in.zw));
    float reach = cat_eye_blur_reach(reach_in.x, reach_in.y, cat_in.xy, reach_in.w, cat_in.zw,
                                     reach_in.z > 0.5);
    outputs[4 * i + 2] = vec4(reach, 0.0, 0.0, 0.0);
    vec2 centre = cat_in.xy;
    CatLens pressed = cat_lens_of(centre);
    outputs[4 * i + 3] = vec4(cat_eye_lens(map_in.zw, centre),
                              cat_eye_pressed_weight(pressed, map_in.zw, 0.9 * centre, 0.1),
                              cat_lens_area(pressed));
}
