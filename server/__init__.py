"""The hidden-truth evaluation server: hidden suites, an HTTP service taking predictions and scoring them
off the request path, and its client (docs/server.md)."""
