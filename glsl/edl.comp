#version 460
// Eye-dome lighting (Boucheny 2009, as Potree and CloudCompare shade point
// clouds), on the G-buffer before depth of field so that the blur acts on
// the shaded image: each pixel's color is scaled by
//   exp(−300 · strength · (1/8) Σ_n max(0, log2 z − log2 z_n))
// over 8 neighbours at `radius_px` (pixel offsets rounded), z the eye depth.
// A neighbour that sees only background adds nothing; a background pixel
// beside a point adds 100 per such neighbour (the outline). A pixel whose
// shade is 1 (a surface facing the camera, no edge near) is not written:
// its bits stay the G-buffer's.

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform image2D color;
layout(binding = 1, rgba32f) uniform readonly image2D eye;

layout(push_constant, std430) uniform Push {
    ivec2 extent;
    float strength;
    float radius_px;
} pc;

bool seen(float z) {
    return z > 0.0 && !isinf(z) && !isnan(z);
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    float z = imageLoad(eye, p).z;
    bool background = !seen(z);
    float sum = 0.0;
    for (int i = 0; i < 8; ++i) {
        float a = float(i) * 0.78539816;
        ivec2 q = p + ivec2(round(pc.radius_px * vec2(cos(a), sin(a))));
        if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, pc.extent))) {
            continue;
        }
        float zn = imageLoad(eye, q).z;
        if (!seen(zn)) {
            continue;
        }
        sum += background ? 100.0 : max(0.0, log2(z) - log2(zn));
    }
    float shade = exp(-300.0 * pc.strength * sum / 8.0);
    if (shade < 1.0) {
        vec4 c = imageLoad(color, p);
        imageStore(color, p, vec4(c.rgb * shade, c.a));
    }
}
