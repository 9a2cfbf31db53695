"""The rivet command line."""
