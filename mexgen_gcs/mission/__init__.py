"""mexgen_gcs.mission layer (see ARCHITECTURE.md)."""
