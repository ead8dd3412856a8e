"""mexgen-gcs: ground control for finding VHF radio-tagged objects with MexGen planning."""

__version__ = "0.1.0"
