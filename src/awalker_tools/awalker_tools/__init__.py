"""awalker tools: bag conversion, replay, synthesis, tracking runs, evaluation, the CLI."""
