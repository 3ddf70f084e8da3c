// Shared by the meshlets-gl draw's shader stages (paramlod/meshlod/draw.py: MeshDraw), which
// prepend "#version 450 core", the PL_* defines and the prelude (paramlod.core.layouts.glsl_prelude:
// the records' PL_INST_*, PL_MAT_* offsets and the Cluster struct).

// The scene's mesh instances and clusters (paramlod.meshlod.buffers: MeshInstances, MeshArrays),
// read-only shader storage buffers.
layout(std430, binding = 0) readonly buffer PlInstF { float pl_inst_f[]; };      // [n][PL_INST_F]
layout(std430, binding = 1) readonly buffer PlInstU { uint pl_inst_u[]; };       // [n][PL_INST_U]
layout(std430, binding = 2) readonly buffer PlMaterials { vec4 pl_materials[]; }; // rgb, specular
layout(std430, binding = 3) readonly buffer PlClusters { Cluster pl_clusters[]; };

uniform mat4 u_view;        // world -> view
uniform mat4 u_proj;        // view -> clip

#include "common/rows.glsl"

#ifdef PL_VIEWS
// The views of a multi-view draw (MeshDraw.draw_views): world -> view and view -> clip of each.
struct PlView { mat4 view; mat4 proj; };
layout(std140, binding = 0) uniform PlViews { PlView pl_views[PL_MAX_VIEWS]; };
#endif
