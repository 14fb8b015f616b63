"""What a run shows: metrics, detection scores and plots."""
