// Flattened 2-D dispatch: lavapipe (and the Vulkan minimum) caps workgroups at 65535 per
// dimension, so grids larger than 65535*64 threads use y as the high part.
uint global_index() {
    return gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
}
