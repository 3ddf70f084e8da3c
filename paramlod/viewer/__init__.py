"""The interactive viewer (docs/viewer.md): app (window and frame loop), controls (cameras, key map),
hud (text overlay), reload (sources and file watching), script (scripted runs, recording),
notebook (pl.show)."""
