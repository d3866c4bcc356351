#version 460
// Layered DOF, pass 4, once per depth slice, back to front (DESIGN §6):
// per row, the prefix sum of the slice's row differences gives each
// pixel's spread premultiplied color C and coverage A (and clears the
// differences for the next slice); the slice's color C / A goes over what
// lies behind with alpha min(A, 1). The farthest slice goes over the
// background; the nearest writes the result.
//
// Two forms of one sum (src/passes/kernel_sizes.rs chooses by device):
// a row per invocation, 64 rows a workgroup (SHARED_ROWS false: a CPU
// device, whose few lanes the rows fill), or a workgroup per row
// (SHARED_ROWS true, the workgroup's size set by ROW_THREADS: a GPU, whose
// thousands of lanes a frame's thousand rows would leave idle), each
// invocation summing ITEMS columns and the workgroup scanning their sums.
// The sums are of integers (layered_fixed.glsl), so both forms give the
// same bits.
#include "lens.glsl"
#include "layered_push.glsl"
#include "layered_fixed.glsl"

// The workgroup's size (specialization constant 4): 64 rows, or a row's
// ROW_THREADS invocations.
layout(local_size_x = 64, local_size_x_id = 4) in;
layout(constant_id = 5) const bool SHARED_ROWS = false;
const uint ROW_THREADS = gl_WorkGroupSize.x;

// Columns an invocation of a shared row takes per step.
const int ITEMS = 4;

layout(binding = 0, std430) buffer Differences { uint64_t differences[]; };
layout(binding = 1, rgba32f) uniform image2D behind;             // rgb, alpha: coverage so far
layout(binding = 2, rgba16f) uniform writeonly image2D result;
// Per row, the columns the slice's differences touch (layered_spread.comp);
// elsewhere the slice adds nothing, and a slice between the farthest and
// the nearest leaves those pixels as they are. Cleared for the next slice.
layout(binding = 3, std430) buffer RowSpans { uint row_spans[]; };

// A shared row's scan of its invocations' sums, and its span.
shared uint64_t scan_rg[ROW_THREADS];
shared uint64_t scan_ba[ROW_THREADS];
shared int span[2];

// The slice's pixel (x, y) from the prefix sums (rg, ba) of its row.
void composite(int x, int y, uint64_t rg, uint64_t ba) {
    bool farthest = pc.slice == pc.slices - 1;
    bool nearest = pc.slice == 0;
    vec4 spread = vec4(unpack(rg), unpack(ba));
    float a = max(spread.a, 0.0);
    float alpha = min(a, 1.0);
    vec3 rgb = pc.gaussian_layers != 0u ? spread.rgb : max(spread.rgb, vec3(0.0));
    vec3 color = a > 1.0 ? rgb / a : rgb;
    vec4 under = farthest ? vec4(pc.background.rgb, 0.0) : imageLoad(behind, ivec2(x, y));
    vec4 over = vec4(color + under.rgb * (1.0 - alpha), alpha + under.a * (1.0 - alpha));
    if (nearest) {
        imageStore(result, ivec2(x, y), over);
    } else {
        imageStore(behind, ivec2(x, y), over);
    }
}

// The columns a row's loop visits: every column for the farthest and the
// nearest slice, else the span of the differences.
ivec2 visited(int from, int to) {
    bool every = pc.slice == pc.slices - 1 || pc.slice == 0;
    return every ? ivec2(0, pc.extent.x - 1) : ivec2(from, to);
}

// The differences of column x of `row` where it lies in [from, to]
// (cleared for the next slice), else zero.
u64vec2 take(int row, int x, int from, int to) {
    if (x < from || x > to) {
        return u64vec2(0ul);
    }
    uint at = 2u * uint(row * pc.extent.x + x);
    u64vec2 d = u64vec2(differences[at], differences[at + 1u]);
    differences[at] = 0ul;
    differences[at + 1u] = 0ul;
    return d;
}

void row_alone(int row, int y) {
    int from = pc.extent.x - int(row_spans[2 * row]);
    int to = int(row_spans[2 * row + 1]) - 1;
    row_spans[2 * row] = 0u;
    row_spans[2 * row + 1] = 0u;
    ivec2 columns = visited(from, to);
    u64vec2 sum = u64vec2(0ul);
    for (int x = columns.x; x <= columns.y; ++x) {
        sum += take(row, x, from, to);
        composite(x, y, sum.x, sum.y);
    }
}

// The row by the workgroup: ROW_THREADS · ITEMS columns a step, each
// invocation's ITEMS consecutive ones, their sums scanned across the
// workgroup (Hillis and Steele) and carried to the next step. Every
// branch before a barrier is the same for the whole workgroup.
void row_shared(int row, int y) {
    uint t = gl_LocalInvocationID.x;
    if (t == 0u) {
        span[0] = pc.extent.x - int(row_spans[2 * row]);
        span[1] = int(row_spans[2 * row + 1]) - 1;
        row_spans[2 * row] = 0u;
        row_spans[2 * row + 1] = 0u;
    }
    barrier();
    int from = span[0];
    int to = span[1];
    ivec2 columns = visited(from, to);
    u64vec2 carry = u64vec2(0ul);
    for (int start = columns.x; start <= columns.y; start += int(ROW_THREADS) * ITEMS) {
        int x0 = start + int(t) * ITEMS;
        u64vec2 d[ITEMS];
        u64vec2 own = u64vec2(0ul);
        for (int i = 0; i < ITEMS; ++i) {
            d[i] = u64vec2(0ul);
            if (x0 + i <= columns.y) {
                d[i] = take(row, x0 + i, from, to);
            }
            own += d[i];
        }
        scan_rg[t] = own.x;
        scan_ba[t] = own.y;
        barrier();
        for (uint step = 1u; step < ROW_THREADS; step <<= 1) {
            u64vec2 before = t >= step ? u64vec2(scan_rg[t - step], scan_ba[t - step]) : u64vec2(0ul);
            barrier();
            scan_rg[t] += before.x;
            scan_ba[t] += before.y;
            barrier();
        }
        // What the columns before this invocation's sum to.
        u64vec2 sum = carry + u64vec2(scan_rg[t], scan_ba[t]) - own;
        for (int i = 0; i < ITEMS; ++i) {
            sum += d[i];
            if (x0 + i <= columns.y) {
                composite(x0 + i, y, sum.x, sum.y);
            }
        }
        carry += u64vec2(scan_rg[ROW_THREADS - 1u], scan_ba[ROW_THREADS - 1u]);
        barrier();
    }
}

void main() {
    int row = int(SHARED_ROWS ? gl_WorkGroupID.x : gl_GlobalInvocationID.x);
    int y = pc.band_y0 + row;
    if (row >= pc.band_rows || y >= pc.extent.y) {
        return;
    }
    if (SHARED_ROWS) {
        row_shared(row, y);
    } else {
        row_alone(row, y);
    }
}
