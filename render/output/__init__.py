"""Outputs: tone mapping, videos, figures, metrics, compositing, denoising, comparison, reports and sweep summaries.

Nothing here imports a renderer: these modules read the files that the render stages write. Only the
denoiser's guide buffers (guides.py) trace the scene folder, with the shared ray engine (render/engine.py)."""
