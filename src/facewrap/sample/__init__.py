"""The built-in sample: a procedural face template and scans with ground truth."""
