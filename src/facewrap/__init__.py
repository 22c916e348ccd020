"""facewrap: wrap templates onto face scans, transfer deformations, make avatar blendshapes."""
