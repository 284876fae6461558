"""Rendering: scene description, optical presets, the PTPB core's Python face, references, compositing."""
