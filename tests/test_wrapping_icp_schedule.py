"""The non-rigid ICP schedule (facewrap.wrapping.icp.schedule) and the defaults."""

import pytest

from facewrap.wrapping import Stage, default_schedule


def test_default_schedules_go_from_stiff_to_loose():
    for model in ("affine", "graph", "hybrid"):
        s = default_schedule(model)
        stiff = [st.smooth_weight for st in s]
        assert stiff == sorted(stiff, reverse=True), model
        assert s[0].data_weight == 0 or model in ("affine", "hybrid")
        # and coarse to fine in node count, ending on the model's own graph
        spacing = [st.node_spacing_factor for st in s]
        assert spacing == sorted(spacing, reverse=True) and spacing[-1] == 1.0, model
    with pytest.raises(ValueError, match="node_spacing_factor"):
        Stage(node_spacing_factor=0.0)




def test_a_model_without_a_schedule_is_refused():
    with pytest.raises(ValueError, match="no default schedule"):
        default_schedule("rbf")
