"""Episode loop, command line, benchmarks and viewers: composes sim, dodt and planner."""
