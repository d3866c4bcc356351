#version 460
// Projects one point to a square point sprite (DESIGN §2, §3): pixel
// position from the thin-lens camera, sheared by the lens offset for lens
// position pc.lens_u, size from the splat's world diameter or pc.splat_px.
#include "splat_raster.glsl"
#include "lens.glsl"
#include "splat_project.glsl"

layout(location = 0) in vec4 in_position_size; // xyz world, w world diameter
layout(location = 1) in vec4 in_color;          // linear RGB

layout(location = 0) flat out vec3 v_color;
layout(location = 1) flat out float v_z;
layout(location = 2) flat out float v_diameter; // world units, for the depth peel
layout(location = 3) flat out vec3 v_disc;      // centre (framebuffer px) and radius, for disc splats

void main() {
    v_color = in_color.rgb;
    Projected s;
    bool inside = project_splat(in_position_size, pc.jitter, s);
    v_z = s.z;
    v_diameter = s.diameter;
    v_disc = vec3(0.0);
    if (!inside) {
        // Behind the eye or outside the depth range: outside the clip volume.
        gl_Position = vec4(0.0, 0.0, -2.0, 1.0);
        gl_PointSize = 1.0;
        return;
    }
    gl_PointSize = s.size_px;
    v_disc = vec3(s.p, 0.5 * s.size_px);
    // Framebuffer coordinate p ↦ NDC; depth linear in eye z (D32 float).
    gl_Position = vec4(2.0 * s.p / pc.extent - 1.0, (s.z - pc.near) / (pc.far - pc.near), 1.0);
}
