"""The host: plugin registry, configuration, and the pipelines that run the stages."""
