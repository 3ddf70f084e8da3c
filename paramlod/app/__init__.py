"""Commands: CLI, scene files, gallery, glyphs, surfel commands, benchmarks."""
