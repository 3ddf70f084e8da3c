// Background pass of targets drawn directly (GLTargets.direct in paramlod/renderers/gl_targets.py:
// noAA, whose fragments write the output targets themselves, so there is no resolve): a
// full-screen triangle on the far plane (tess_resolve_vertex.glsl with PL_FAR) into the depth
// buffer alone, depth-tested "<=" against its clear value 1, so it reaches exactly the pixels
// nothing was drawn into. It writes nothing (begin cleared their object id and image; the other
// arrays are blanked where the id is 0 when read); an occlusion query counts them, and the pixels
// written are the rest.
void main() {
}
