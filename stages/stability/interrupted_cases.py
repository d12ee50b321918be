"""Interrupted runs: SIGTERM mid-training, rerun, same final weights as an uninterrupted run."""
