// The four colour attachments of GLTargets (paramlod/renderers/gl_targets.py), written by every
// fragment stage that draws into them (tess, mesh, carry, resolve): 0 colour RGBA16F (linear RGB;
// alpha 0 = nothing drawn), 1 linear view depth R32F, 2 world-space normal RGBA16F, 3 object id
// R32UI.
layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_depth;
layout(location = 2) out vec4 out_normal;
layout(location = 3) out uint out_object;
