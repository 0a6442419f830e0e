"""A read-only web dashboard fed by the same Zenoh keys as ``companion monitor``."""
