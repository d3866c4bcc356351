#version 460
// One pass of a stable least-significant-digit radix sort of 32-bit keys
// with 32-bit values (src/passes/radix_sort.rs): 4-bit digits, blocks of
// BLOCK keys, each invocation a run of ITEMS consecutive keys, so that the
// order within a block is the invocations' order. Three stages:
//   0: each block's count of every digit, hist[digit * blocks + block];
//   1: one workgroup: the exclusive prefix sum of hist, in place (digit
//      major, so a digit's keys of every block come before the next
//      digit's);
//   2: each block writes its keys and values where hist says, in order.
// The number of keys is min(counts[count_index], capacity): a count the
// GPU wrote (a sort of the tile list) or the host did.
layout(local_size_x = 256) in;

const uint GROUP = 256u;
const uint ITEMS = 16u;
const uint BLOCK = GROUP * ITEMS;
const uint RADIX = 16u;

layout(binding = 0, std430) readonly buffer KeysIn { uint keys_in[]; };
layout(binding = 1, std430) readonly buffer ValuesIn { uint values_in[]; };
layout(binding = 2, std430) writeonly buffer KeysOut { uint keys_out[]; };
layout(binding = 3, std430) writeonly buffer ValuesOut { uint values_out[]; };
layout(binding = 4, std430) buffer Hist { uint hist[]; };
layout(binding = 5, std430) readonly buffer Counts { uint counts[]; };

layout(push_constant) uniform Push {
    uint stage;
    uint shift;        // the digit's lowest bit
    uint count_index;  // counts[count_index] keys ...
    uint capacity;     // ... at most this many
} pc;

shared uint bins[RADIX];
// Per invocation, its digits' counts, two 16-bit counts a word.
shared uint packed[RADIX / 2u][GROUP];
shared uint partial[GROUP];

uint digit_of(uint key) {
    return (key >> pc.shift) & (RADIX - 1u);
}

// Inclusive prefix sum of partial[] over the workgroup (Hillis-Steele).
void scan_partial(uint t) {
    for (uint off = 1u; off < GROUP; off <<= 1u) {
        uint add = t >= off ? partial[t - off] : 0u;
        barrier();
        partial[t] += add;
        barrier();
    }
}

void main() {
    uint n = min(counts[pc.count_index], pc.capacity);
    uint blocks = (n + BLOCK - 1u) / BLOCK;
    uint t = gl_LocalInvocationID.x;
    uint block = gl_WorkGroupID.x;
    if (pc.stage == 1u) {
        // One workgroup: each invocation a run of the table.
        uint len = RADIX * blocks;
        uint run = (len + GROUP - 1u) / GROUP;
        uint begin = min(t * run, len);
        uint end = min(begin + run, len);
        uint sum = 0u;
        for (uint i = begin; i < end; i++) {
            sum += hist[i];
        }
        partial[t] = sum;
        barrier();
        scan_partial(t);
        uint base = partial[t] - sum;
        for (uint i = begin; i < end; i++) {
            uint c = hist[i];
            hist[i] = base;
            base += c;
        }
        return;
    }
    if (block >= blocks) {
        return; // the whole workgroup: a tile list shorter than its capacity
    }
    uint first = block * BLOCK + t * ITEMS;
    if (pc.stage == 0u) {
        if (t < RADIX) {
            bins[t] = 0u;
        }
        barrier();
        for (uint k = 0u; k < ITEMS; k++) {
            uint i = first + k;
            if (i < n) {
                atomicAdd(bins[digit_of(keys_in[i])], 1u);
            }
        }
        barrier();
        if (t < RADIX) {
            hist[t * blocks + block] = bins[t];
        }
        return;
    }
    // Stage 2: this invocation's counts, then their exclusive prefix over
    // the invocations before it, digit by digit.
    uint mine[RADIX / 2u];
    for (uint w = 0u; w < RADIX / 2u; w++) {
        mine[w] = 0u;
    }
    for (uint k = 0u; k < ITEMS; k++) {
        uint i = first + k;
        if (i < n) {
            uint d = digit_of(keys_in[i]);
            mine[d >> 1u] += 1u << (16u * (d & 1u));
        }
    }
    for (uint w = 0u; w < RADIX / 2u; w++) {
        packed[w][t] = mine[w];
    }
    barrier();
    for (uint off = 1u; off < GROUP; off <<= 1u) {
        uint add[RADIX / 2u];
        for (uint w = 0u; w < RADIX / 2u; w++) {
            add[w] = t >= off ? packed[w][t - off] : 0u;
        }
        barrier();
        for (uint w = 0u; w < RADIX / 2u; w++) {
            packed[w][t] += add[w];
        }
        barrier();
    }
    // Exclusive: the inclusive sums less this invocation's own counts (no
    // 16-bit count exceeds BLOCK, so no borrow crosses halves).
    uint before[RADIX / 2u];
    for (uint w = 0u; w < RADIX / 2u; w++) {
        before[w] = packed[w][t] - mine[w];
    }
    for (uint k = 0u; k < ITEMS; k++) {
        uint i = first + k;
        if (i < n) {
            uint key = keys_in[i];
            uint d = digit_of(key);
            uint lane = 16u * (d & 1u);
            uint rank = (before[d >> 1u] >> lane) & 0xFFFFu;
            before[d >> 1u] += 1u << lane;
            uint at = hist[d * blocks + block] + rank;
            keys_out[at] = key;
            values_out[at] = values_in[i];
        }
    }
}
