"""Several runs side by side: the paper's comparison."""
