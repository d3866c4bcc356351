#version 460
// One layer of gaussian_layers.comp's buffers into the images of a
// G-buffer layer (src/gaussian_render.rs): what the layered method reads.
layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, std430) readonly buffer LayerColor { uvec2 layer_color[]; };
layout(binding = 1, std430) readonly buffer LayerEye { vec4 layer_eye[]; };
layout(binding = 2, rgba16f) uniform writeonly image2D color;
layout(binding = 3, rgba32f) uniform writeonly image2D eye;

layout(push_constant) uniform Push {
    uint width;
    uint height;
    uint layer;
} pc;

void main() {
    uvec2 p = gl_GlobalInvocationID.xy;
    if (p.x >= pc.width || p.y >= pc.height) {
        return;
    }
    uint at = pc.layer * pc.width * pc.height + p.y * pc.width + p.x;
    uvec2 words = layer_color[at];
    imageStore(color, ivec2(p), vec4(unpackHalf2x16(words.x), unpackHalf2x16(words.y)));
    imageStore(eye, ivec2(p), layer_eye[at]);
}
