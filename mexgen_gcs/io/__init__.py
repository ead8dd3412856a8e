"""mexgen_gcs.io layer (see ARCHITECTURE.md)."""
