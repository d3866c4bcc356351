// Ray distribution buffer (Zhao §3.2, DESIGN §5), scatter: every G-buffer
// pixel P offers itself to the lens bins of the output pixels its rays
// reach, through `offer(q, bin, depth_bits, source)`, which the including
// shader defines (rdb_scatter.comp: two passes of 32-bit image atomics;
// rdb_scatter64.comp: one pass of 64-bit buffer atomics). Each bin keeps the
// smallest depth (float bits; z > 0, so bit order is numeric order), and
// among the sources at that depth the smallest index: deterministic.
//   centre mode: bin b of Q receives P when P moved by its lens offset for
//     the bin's centre u_b lands on Q (q = p + floor(offset + 0.5)); with
//     the cat's eye of a round aperture (pc.cat_lens), u_b pressed into
//     the part of the lens Q sees (below).
//   pairs mode: for every Q inside P's CoC, only the bin holding
//     u = sign · 2 (q − p) / c receives P; c < 2 fills every bin of P itself.
// Needs, before the include: gbuffer_eye, lens_u[], and pc with extent,
// origin, scan_origin, bins, pairs, f_px, aperture_radius, focus_distance,
// window_origin, frame_size, cat_eye and cat_lens.
#include "lens.glsl"
#include "concentric.glsl"
#include "aperture.glsl"

void main() {
    ivec2 p = pc.scan_origin + ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    float z = imageLoad(gbuffer_eye, p).z;
    uint depth_bits = floatBitsToUint(z);
    uint source = uint(p.y * pc.extent.x + p.x);
    ivec2 po = p - pc.origin; // P in output pixel coordinates
    int n2 = pc.bins * pc.bins;
    float c = coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    if (pc.pairs == 0u) {
        if (APERTURE_CODE && pc.cat_lens != 0u) {
            // The cat's eye of a round aperture: bin b of the pixel Q that
            // P's ray lands on stands for lens position u_b pressed into
            // the part of the lens Q sees (cat_eye_lens), so that every
            // bin of a pixel lies where it sees. Q is found by one
            // fixed-point step from P's own circle: the circle's centre is
            // affine in the pixel (−2S/|frame/2| per pixel), so the first
            // landing's circle is P's moved by its offset. The ellipse
            // bulges past the lens's circle by up to √(9/8) − 1 of its
            // radius, where the resolve's ramp still weighs a bin a little;
            // its lens position is kept to the circle, so that no offset
            // passes c/2, which the guard band and the tiles' apron hold.
            float k = 0.5 * signed_coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
            vec2 own = cat_eye_centre(pc.window_origin + po, pc.frame_size, pc.cat_eye);
            CatLens at_p = cat_lens_of(own);
            float moved = 2.0 * pc.cat_eye * k / length(0.5 * vec2(pc.frame_size));
            for (int b = 0; b < n2; ++b) {
                vec2 u = lens_u[b];
                vec2 landing = own - moved * cat_lens_at(at_p, u);
                vec2 pressed = cat_eye_lens(u, landing);
                vec2 offset = k * (pressed * min(1.0, inversesqrt(max(dot(pressed, pressed), 1.0e-30))));
                offer(po + ivec2(floor(offset + 0.5)), b, depth_bits, source);
            }
            return;
        }
        for (int b = 0; b < n2; ++b) {
            vec2 offset = lens_offset_px(z, lens_u[b], pc.f_px, pc.aperture_radius, pc.focus_distance);
            offer(po + ivec2(floor(offset + 0.5)), b, depth_bits, source);
        }
        return;
    }
    if (c < 2.0) {
        for (int b = 0; b < n2; ++b) {
            offer(po, b, depth_bits, source);
        }
        return;
    }
    float sign_z = z >= pc.focus_distance ? 1.0 : -1.0;
    float r2 = 0.25 * c * c;
    int r = int(floor(0.5 * c));
    for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
            if (float(dx * dx + dy * dy) > r2) {
                continue;
            }
            vec2 u = sign_z * 2.0 * vec2(dx, dy) / c;
            vec2 a = concentric_square(u);
            ivec2 cell = clamp(ivec2(floor((a + 1.0) * 0.5 * float(pc.bins))), ivec2(0), ivec2(pc.bins - 1));
            offer(po + ivec2(dx, dy), cell.y * pc.bins + cell.x, depth_bits, source);
        }
    }
}
