#version 460
// Projects one point to a square point sprite (DESIGN §2, §3): pixel
// position from the thin-lens camera, sheared by the lens offset for lens
// position pc.lens_u, size from the splat's world diameter or pc.splat_px.
#include "splat_raster.glsl"
#include "lens.glsl"

layout(location = 0) in vec4 in_position_size; // xyz world, w world diameter
layout(location = 1) in vec4 in_color;          // linear RGB

layout(location = 0) flat out vec3 v_color;
layout(location = 1) flat out float v_z;
layout(location = 2) flat out float v_diameter; // world units, for the depth peel

void main() {
    vec3 d = in_position_size.xyz - pc.eye.xyz;
    vec3 e = vec3(dot(d, pc.right.xyz), dot(d, pc.up.xyz), dot(d, pc.forward.xyz));
    v_color = in_color.rgb;
    v_z = e.z;
    v_diameter = 0.0;
    if (e.z <= pc.near || e.z >= pc.far) {
        // Behind the eye or outside the depth range: outside the clip volume.
        gl_Position = vec4(0.0, 0.0, -2.0, 1.0);
        gl_PointSize = 1.0;
        return;
    }
    vec2 p = vec2(pc.center.x + pc.f_px * e.x / e.z, pc.center.y - pc.f_px * e.y / e.z);
    p += pc.jitter + lens_offset_px(e.z, pc.lens_u, pc.f_px, pc.aperture_radius, pc.focus_distance);
    float size = pc.splat_px > 0.0 ? pc.splat_px : pc.f_px * in_position_size.w / e.z;
    v_diameter = pc.splat_px > 0.0 ? pc.splat_px * e.z / pc.f_px : in_position_size.w;
    gl_PointSize = clamp(size, pc.min_point_size, pc.max_point_size);
    // Framebuffer coordinate p ↦ NDC; depth linear in eye z (D32 float).
    gl_Position = vec4(2.0 * p / pc.extent - 1.0, (e.z - pc.near) / (pc.far - pc.near), 1.0);
}
