#version 460
// Resolves the K×K sample rasters into the G-buffer as they are drawn
// (DESIGN §3): after sample s, adds its color to the running sum and keeps
// the nearest eye position (strict <, so ties go to the lowest sample index)
// and the coverage count. After the last sample, writes the mean color and
// the coverage fraction. Uncovered pixels are the background surface at
// z = +inf.

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D sample_color;
layout(binding = 1, rgba32f) uniform readonly image2D sample_eye;
layout(binding = 2, rgba32f) uniform image2D color_sum;
layout(binding = 3, rgba32f) uniform image2D gbuffer_eye;   // w: covered samples, then fraction
layout(binding = 4, rgba16f) uniform writeonly image2D gbuffer_color;

layout(push_constant, std430) uniform Push {
    ivec2 extent;
    uint sample_index;
    uint sample_count;
} pc;

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    vec4 c = imageLoad(sample_color, p);
    vec4 e = imageLoad(sample_eye, p);
    bool covered = e.w > 0.0;
    float inf = uintBitsToFloat(0x7f800000u);
    vec4 sum;
    vec4 best;
    if (pc.sample_index == 0u) {
        sum = c;
        best = covered ? vec4(e.xyz, 1.0) : vec4(0.0, 0.0, inf, 0.0);
    } else {
        sum = imageLoad(color_sum, p) + c;
        best = imageLoad(gbuffer_eye, p);
        if (covered) {
            if (e.z < best.z) {
                best.xyz = e.xyz;
            }
            best.w += 1.0;
        }
    }
    if (pc.sample_index + 1u == pc.sample_count) {
        float n = float(pc.sample_count);
        imageStore(gbuffer_color, p, sum / n);
        best.w /= n;
    } else {
        imageStore(color_sum, p, sum);
    }
    imageStore(gbuffer_eye, p, best);
}
