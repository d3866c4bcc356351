#version 460
// Every Gaussian through one lens point (src/gaussian_render.rs): the
// projection of crate::gaussians::project_through, mirrored step by step
// (the CPU code is the reference). Writes the projected Gaussian, its
// depth key and index for the sort, and how many tiles it covers (0 where
// culled, with the largest key so that it sorts last).
#include "gaussian.glsl"

layout(local_size_x = 256) in;

layout(binding = 0, std430) readonly buffer Gaussians { Gaussian gaussians[]; };
// SH coefficients of Gaussians [0, sh_split) and [sh_split, count): two
// buffers, so that 10^6 Gaussians of degree 3 fit lavapipe's 128 MiB.
layout(binding = 1, std430) readonly buffer Sh { float sh[]; };
layout(binding = 6, std430) readonly buffer ShRest { float sh_rest[]; };
layout(binding = 2, std430) writeonly buffer Out { Projected projected[]; };
layout(binding = 3, std430) writeonly buffer Keys { uint keys[]; };
layout(binding = 4, std430) writeonly buffer Values { uint values[]; };
layout(binding = 5, std430) writeonly buffer Touched { uint touched[]; };

layout(push_constant) uniform Push {
    vec4 right;        // eye basis (world), and the eye position in w of
    vec4 up;           // the three: eye = (right.w, up.w, forward.w)
    vec4 forward;
    vec4 lens_world;   // the lens point (world), focus distance S
    vec2 lens;         // the lens point, eye x and y
    float f_px;
    uint count;
    uint width;
    uint height;
    uint sh_degree;
    uint sh_stride;    // floats of SH per Gaussian
    uint sh_split;     // the first Gaussian whose SH is in sh_rest
    float near_z;      // centres at most this eye depth are culled
} pc;

const float SH_C0 = 0.28209479177387814;
const float SH_C1 = 0.4886025119029199;
const float SH_C2[5] = float[](1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                               -1.0925484305920792, 0.5462742152960396);
const float SH_C3[7] = float[](-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                               0.3731763325901154, -0.4570457994644658, 1.445305721320277,
                               -0.5900435899266435);

vec3 coef(uint g, uint k) {
    if (g < pc.sh_split) {
        uint base = g * pc.sh_stride + 3u * k;
        return vec3(sh[base], sh[base + 1u], sh[base + 2u]);
    }
    uint base = (g - pc.sh_split) * pc.sh_stride + 3u * k;
    return vec3(sh_rest[base], sh_rest[base + 1u], sh_rest[base + 2u]);
}

// crate::gaussians::sh_color.
vec3 sh_color(uint g, vec3 d) {
    vec3 result = SH_C0 * coef(g, 0u);
    if (pc.sh_degree > 0u) {
        float x = d.x, y = d.y, z = d.z;
        result += -SH_C1 * y * coef(g, 1u) + SH_C1 * z * coef(g, 2u) - SH_C1 * x * coef(g, 3u);
        if (pc.sh_degree > 1u) {
            float xx = x * x, yy = y * y, zz = z * z;
            float xy = x * y, yz = y * z, xz = x * z;
            result += SH_C2[0] * xy * coef(g, 4u) + SH_C2[1] * yz * coef(g, 5u)
                + SH_C2[2] * (2.0 * zz - xx - yy) * coef(g, 6u) + SH_C2[3] * xz * coef(g, 7u)
                + SH_C2[4] * (xx - yy) * coef(g, 8u);
            if (pc.sh_degree > 2u) {
                result += SH_C3[0] * y * (3.0 * xx - yy) * coef(g, 9u)
                    + SH_C3[1] * xy * z * coef(g, 10u)
                    + SH_C3[2] * y * (4.0 * zz - xx - yy) * coef(g, 11u)
                    + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * coef(g, 12u)
                    + SH_C3[4] * x * (4.0 * zz - xx - yy) * coef(g, 13u)
                    + SH_C3[5] * z * (xx - yy) * coef(g, 14u)
                    + SH_C3[6] * x * (xx - 3.0 * yy) * coef(g, 15u);
            }
        }
    }
    return max(result + vec3(0.5), vec3(0.0));
}

void cull(uint g) {
    keys[g] = 0xFFFFFFFFu;
    values[g] = g;
    touched[g] = 0u;
}

void main() {
    uint g = gl_GlobalInvocationID.x;
    if (g >= pc.count) {
        return;
    }
    Gaussian gs = gaussians[g];
    vec3 p = gs.position_opacity.xyz;
    vec3 eye = vec3(pc.right.w, pc.up.w, pc.forward.w);
    vec3 q = p - eye;
    vec3 e0 = vec3(dot(q, pc.right.xyz), dot(q, pc.up.xyz), dot(q, pc.forward.xyz));
    if (!(e0.z > pc.near_z)) {
        cull(g);
        return;
    }
    float s = pc.lens_world.w;
    vec2 shear = pc.lens / s;
    vec3 e = vec3(e0.xy + shear * e0.z - pc.lens, e0.z);
    // W: rows right, up, forward, sheared.
    vec3 w0 = pc.right.xyz + shear.x * pc.forward.xyz;
    vec3 w1 = pc.up.xyz + shear.y * pc.forward.xyz;
    vec3 w2 = pc.forward.xyz;
    float f = pc.f_px;
    float lim_x = 1.3 * (float(pc.width) / (2.0 * f));
    float lim_y = 1.3 * (float(pc.height) / (2.0 * f));
    float z = e.z;
    float tx = clamp(e.x / z, -lim_x, lim_x) * z;
    float ty = clamp(e.y / z, -lim_y, lim_y) * z;
    // Rows of T = J W.
    vec3 j0 = vec3(f / z, 0.0, -f * tx / (z * z));
    vec3 j1 = vec3(0.0, -f / z, f * ty / (z * z));
    vec3 t0 = j0.x * w0 + j0.y * w1 + j0.z * w2;
    vec3 t1 = j1.x * w0 + j1.y * w1 + j1.z * w2;
    mat3 sigma = mat3(gs.cov_a.x, gs.cov_a.y, gs.cov_a.z,
                      gs.cov_a.y, gs.cov_a.w, gs.cov_b.x,
                      gs.cov_a.z, gs.cov_b.x, gs.cov_b.y);
    vec3 st0 = sigma * t0;
    vec3 st1 = sigma * t1;
    float a = dot(t0, st0) + 0.3;
    float b = dot(t0, st1);
    float c = dot(t1, st1) + 0.3;
    float det = a * c - b * b;
    // Also culled: a covariance beyond floats (a huge Gaussian near the
    // eye), whose radius and tiles would not be numbers.
    if (det == 0.0 || isinf(det) || isnan(det)) {
        cull(g);
        return;
    }
    vec3 conic = vec3(c / det, -b / det, a / det);
    float mid = 0.5 * (a + c);
    float lambda1 = mid + sqrt(max(mid * mid - det, 0.1));
    float lambda2 = mid - sqrt(max(mid * mid - det, 0.1));
    // Kept in floats: the tiles clamp it to the image (an int would
    // overflow for a huge Gaussian).
    float radius = ceil(3.0 * sqrt(max(lambda1, lambda2)));
    if (isinf(radius) || isnan(radius)) {
        cull(g);
        return;
    }
    vec2 centre = vec2(float(pc.width) / 2.0 + f * e.x / e.z, float(pc.height) / 2.0 - f * e.y / e.z);
    vec2 at = centre - vec2(0.5);
    ivec2 grid = (ivec2(pc.width, pc.height) + TILE_PX - 1) / TILE_PX;
    float r = radius;
    ivec4 tiles = ivec4(
        int(min(max((at.x - r) / float(TILE_PX), 0.0), float(grid.x))),
        int(min(max((at.x + r + float(TILE_PX) - 1.0) / float(TILE_PX), 0.0), float(grid.x))),
        int(min(max((at.y - r) / float(TILE_PX), 0.0), float(grid.y))),
        int(min(max((at.y + r + float(TILE_PX) - 1.0) / float(TILE_PX), 0.0), float(grid.y))));
    uint area = uint((tiles.y - tiles.x) * (tiles.w - tiles.z));
    if (area == 0u) {
        cull(g);
        return;
    }
    vec3 direction = normalize(p - pc.lens_world.xyz);
    projected[g] = Projected(vec4(centre, e.z, 0.0), vec4(conic, gs.position_opacity.w),
                             vec4(sh_color(g, direction), 0.0), tiles);
    keys[g] = floatBitsToUint(e.z);
    values[g] = g;
    touched[g] = area;
}
