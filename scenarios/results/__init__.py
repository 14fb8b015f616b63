"""What a run shows: metrics, detection scores, encounters, plots, and run.mcap and the live
view for Foxglove."""
