"""mexgen_gcs.config layer (see ARCHITECTURE.md)."""
