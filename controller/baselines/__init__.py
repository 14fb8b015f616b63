"""The paper's two baselines (§IV-B, Appendix): LOS guidance with PID, and a lexicographic planner."""
