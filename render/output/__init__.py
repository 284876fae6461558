"""Outputs: tone mapping, videos, figures, metrics, compositing, comparison, reports and sweep summaries.

Nothing here imports a renderer: these modules read the files that the render stages write."""
