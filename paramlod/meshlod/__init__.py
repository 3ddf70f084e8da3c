"""Mesh level of detail (cluster DAG, LOD chain, skinning): not built yet."""
