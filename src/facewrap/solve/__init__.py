"""Linear algebra shared by wrapping, transfer and avatar: factorisations, normal equations."""
