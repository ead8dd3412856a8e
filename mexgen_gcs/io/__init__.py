"""mexgen_gcs.io layer: ports and adapters (see docs/architecture.md)."""
