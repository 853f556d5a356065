"""What several test folders share: the mock loom harness and the controller helpers."""
