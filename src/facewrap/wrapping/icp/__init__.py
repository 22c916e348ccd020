"""Non-rigid ICP: the one registration engine, its stage schedule and energy terms."""
