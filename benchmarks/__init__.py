"""Speed and accuracy benchmarks; each writes results/bench/<name>.json (DESIGN.md)."""
