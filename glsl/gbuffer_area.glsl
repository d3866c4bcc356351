// The G-buffer's area coverage (`--coverage area`, src/passes/gbuffer_area.rs):
// the compute raster's resolve (gbuffer_resolve_vis_marks.comp) marks the
// pixels whose samples and the ring of their neighbours' nearest samples
// do not all hold one visibility word; the area pass (gbuffer_area.comp),
// dispatched over the marked pixels alone, makes each one's color from
// the visible areas of the nearest splats those samples saw. Shared by
// both: the list of marked pixels (at binding AREA_LIST_BINDING) and the
// window of samples.

// The marked pixels: a VkDispatchIndirectCommand of the area pass (x:
// workgroups of AREA_GROUP), their count, then each pixel (x | y << 16).
layout(binding = AREA_LIST_BINDING, std430) buffer Marked {
    uint marked_dispatch[3];
    uint marked_count;
    uint marked[];
};

// Invocations per workgroup of the area pass, and its workgroups per row
// of the dispatch (the least maxComputeWorkGroupCount a device has; mirror
// src/passes/gbuffer_area.rs).
const uint AREA_GROUP = 64u;
const uint AREA_ROW_GROUPS = 65535u;

// G-buffer pixel p's K×K block of target pixels (`block`, its first),
// and the target pixels [lo, hi) whose samples find its splats: the block
// and a ring one target pixel wide around it (its neighbours' nearest
// samples), within the target, which holds the G-buffer rows
// [first_row, end_row) of a G-buffer `width` pixels wide.
void area_window(ivec2 p, int k, int width, int first_row, int end_row, out ivec2 block,
                 out ivec2 lo, out ivec2 hi) {
    block = (p - ivec2(0, first_row)) * k;
    lo = max(block - 1, ivec2(0));
    hi = min(block + k + 1, ivec2(width, end_row - first_row) * k);
}

// Appends pixel p to the list; the first pixel of each AREA_GROUP opens
// a workgroup of the area pass's dispatch, in rows of AREA_ROW_GROUPS.
void mark(ivec2 p) {
    uint i = atomicAdd(marked_count, 1u);
    marked[i] = uint(p.x) | (uint(p.y) << 16);
    if (i % AREA_GROUP == 0u) {
        uint g = i / AREA_GROUP;
        atomicMax(marked_dispatch[0], min(g + 1u, AREA_ROW_GROUPS));
        atomicMax(marked_dispatch[1], g / AREA_ROW_GROUPS + 1u);
    }
}

// The marked pixel of the area pass's invocation, if there is one.
bool marked_pixel(out ivec2 p) {
    uint g = gl_WorkGroupID.y * AREA_ROW_GROUPS + gl_WorkGroupID.x;
    uint i = g * AREA_GROUP + gl_LocalInvocationID.x;
    if (i >= marked_count) {
        return false;
    }
    uint packed = marked[i];
    p = ivec2(int(packed & 0xffffu), int(packed >> 16));
    return true;
}
