"""mexgen_gcs.ui layer (see ARCHITECTURE.md)."""
