"""The verbs of the ``colonbench`` command line, one module per group: each adds its parsers and runs its verb."""
