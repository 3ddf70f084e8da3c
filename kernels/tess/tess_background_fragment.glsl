// Background pass of targets drawn directly (GLTargets.direct in paramlod/renderers/gl_targets.py:
// noAA, whose fragments write the output targets themselves, so there is no resolve): a
// full-screen triangle on the far plane (tess_resolve_vertex.glsl with PL_FAR), depth-tested
// "<=" against the depth buffer cleared to 1, so it reaches exactly the pixels nothing was drawn
// into this frame, and writes there what the resolve would: colour 0, depth +inf, normal 0, id 0
// and the background's image code. An occlusion query counts them; the pixels written are the rest.
#include "common/targets.glsl"

uniform uvec3 u_background_code;   // linear_to_srgb8 of the background, on the host

void main() {
    out_color = vec4(0.0);
    out_depth = PL_INF;
    out_normal = vec4(0.0);
    out_object = 0u;
    out_image = uvec4(u_background_code, 255u);
}
