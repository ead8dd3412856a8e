"""mexgen_gcs.core layer (see ARCHITECTURE.md)."""
