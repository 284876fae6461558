"""The neutral scene: its model, the builder that turns the config into it, optics and shapes."""
