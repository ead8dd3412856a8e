"""mexgen_gcs.analysis layer (see ARCHITECTURE.md)."""
