"""HTTP and WebSocket routes of the service, with their shared dependencies."""
