"""The offline build of a mesh's level of detail: ``dag`` (the cluster DAG, ``build_dag``; also
``lod="full"``, the original triangles only) and ``chain`` (a discrete chain of whole-mesh levels,
``build_chain``, the baseline the DAG is measured against), both on top of ``meshopt`` (a ctypes
layer over meshoptimizer 0.22's compiled library). Driven by paramlod.meshlod.source (cached
builds), ``paramlod mesh build`` and the mesh-LOD evaluation of ``paramlod bench``."""
