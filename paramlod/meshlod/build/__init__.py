"""The offline build of a mesh's level of detail: ``dag`` (the cluster DAG, ``build_dag``) on top of
``meshopt`` (a ctypes layer over meshoptimizer 0.22's compiled library). Driven by
paramlod.meshlod.source (cached builds) and ``paramlod mesh build``."""
