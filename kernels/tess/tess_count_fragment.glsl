// Count pass after a resolve (GLTargets.resolve in paramlod/renderers/gl_targets.py): a
// full-screen triangle over the resolved depth that discards the pixels nothing was drawn into;
// an occlusion query counts the rest, the pixels written. It writes nothing. A counter that every
// covered pixel of the resolve incremented took an NVIDIA H100 8-13 ms of a 1080p 4xSS+8xMS frame
// (docs/benchmarks/nvidia-h100/direct-gl.md).
uniform sampler2D u_depth;

void main() {
    if (isinf(texelFetch(u_depth, ivec2(gl_FragCoord.xy), 0).r)) discard;
}
