"""The canal world: walls, what stands behind them, obstacles; the built-in demo canal."""
