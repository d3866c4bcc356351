#version 460
// Exclusive prefix sum of u32 values (src/passes/radix_sort.rs, `Scan`):
// out[i] = sum of values[index[j]] for j < i, over n = counts[count_index]
// (or pc.n where count_index is NONE) entries, in three stages:
//   0: each block's sum, sums[block];
//   1: one workgroup: the exclusive prefix sum of sums, in place; the
//      total to counts[total_index] and its maximum over the frame to
//      counts[total_index + 1] (unless total_index is NONE);
//   2: each block's prefix sums from its sum's prefix.
// Values are read through index[] where pc.gather is 1 (values in the
// order of a sort), else in place.
layout(local_size_x = 256) in;

const uint GROUP = 256u;
const uint ITEMS = 16u;
const uint BLOCK = GROUP * ITEMS;
const uint NONE = 0xFFFFFFFFu;

layout(binding = 0, std430) readonly buffer Values { uint values[]; };
layout(binding = 1, std430) readonly buffer Index { uint index[]; };
layout(binding = 2, std430) writeonly buffer Out { uint result[]; };
layout(binding = 3, std430) buffer Sums { uint sums[]; };
layout(binding = 4, std430) buffer Counts { uint counts[]; };

layout(push_constant) uniform Push {
    uint stage;
    uint n;
    uint count_index;
    uint total_index;
    uint gather;
} pc;

shared uint partial[GROUP];

// a + b, or the largest word where it would wrap: a total beyond 32 bits
// stays above any capacity (the host then refuses the frame) instead of
// wrapping to a small one.
uint add_sat(uint a, uint b) {
    uint s = a + b;
    return s < a ? 0xFFFFFFFFu : s;
}

void scan_partial(uint t) {
    for (uint off = 1u; off < GROUP; off <<= 1u) {
        uint add = t >= off ? partial[t - off] : 0u;
        barrier();
        partial[t] = add_sat(partial[t], add);
        barrier();
    }
}

uint value_at(uint i) {
    return pc.gather == 1u ? values[index[i]] : values[i];
}

void main() {
    uint n = pc.count_index == NONE ? pc.n : min(counts[pc.count_index], pc.n);
    uint blocks = (n + BLOCK - 1u) / BLOCK;
    uint t = gl_LocalInvocationID.x;
    if (pc.stage == 1u) {
        uint run = (blocks + GROUP - 1u) / GROUP;
        uint begin = min(t * run, blocks);
        uint end = min(begin + run, blocks);
        uint sum = 0u;
        for (uint i = begin; i < end; i++) {
            sum = add_sat(sum, sums[i]);
        }
        partial[t] = sum;
        barrier();
        scan_partial(t);
        uint base = partial[t] - sum;
        for (uint i = begin; i < end; i++) {
            uint c = sums[i];
            sums[i] = base;
            base = add_sat(base, c);
        }
        if (t == GROUP - 1u && pc.total_index != NONE) {
            uint total = partial[t];
            counts[pc.total_index] = total;
            counts[pc.total_index + 1u] = max(counts[pc.total_index + 1u], total);
        }
        return;
    }
    uint block = gl_WorkGroupID.x;
    if (block >= blocks) {
        return;
    }
    uint first = block * BLOCK + t * ITEMS;
    uint sum = 0u;
    for (uint k = 0u; k < ITEMS; k++) {
        uint i = first + k;
        if (i < n) {
            sum = add_sat(sum, value_at(i));
        }
    }
    partial[t] = sum;
    barrier();
    scan_partial(t);
    if (pc.stage == 0u) {
        if (t == GROUP - 1u) {
            sums[block] = partial[t];
        }
        return;
    }
    // (Where the total saturated, offsets past 2^32 are wrong, but the
    // frame is refused before they are used.)
    uint base = add_sat(sums[block], partial[t] - sum);
    for (uint k = 0u; k < ITEMS; k++) {
        uint i = first + k;
        if (i < n) {
            result[i] = base;
            base = add_sat(base, value_at(i));
        }
    }
}
