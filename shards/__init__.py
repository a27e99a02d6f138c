"""Training shards: the HDF5 schema, manifests, generation in parallel, reading and verification."""
