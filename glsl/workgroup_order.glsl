// The order in which an indirect dispatch's workgroups take the entries of
// its list (src/passes/kernel_sizes.rs, KernelSizes::workgroup_streams).
// A CPU device runs `streams` workgroups at once, in dispatch order, one
// on each of its threads; the list is cut into `streams` parts and
// workgroup w takes entry w / streams of part w % streams, so that the
// workgroups running at once take entries far apart in the list (tiles far
// apart in the frame), whose atomic adds do not fight over the same cache
// lines. A permutation of [0, count); with one stream, w itself.
uint streamed_entry(uint w, uint count, uint streams) {
    uint s = max(streams, 1u);
    uint part = w % s;
    return part * (count / s) + min(part, count % s) + w / s;
}
