"""One router per resource: health, worlds, config, runs and the live WebSocket."""
