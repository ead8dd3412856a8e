"""mexgen_gcs.experiments layer (see ARCHITECTURE.md)."""
