"""Wrap settings (facewrap.wrapping.settings) and the model registry."""

import pytest

from facewrap.params import choices_of
from facewrap.wrapping import MODEL_REGISTRY, MODELS, WrapSettings
from facewrap.wrapping.models import model_spec


def test_weight_range_setting():
    assert WrapSettings().blend_bounds() == (0.0, 1.0)
    assert WrapSettings(weight_range=[]).blend_bounds() is None
    assert WrapSettings(weight_range=None).blend_bounds() is None
    assert WrapSettings(pca_components=5).blend_bounds() is None   # PCA: unbounded
    assert WrapSettings(weight_range=[-1, 2]).blend_bounds() == (-1.0, 2.0)
    for bad in ([1.0, 0.0], [0.0], [0, 1, 2]):
        with pytest.raises(ValueError, match="weight_range"):
            WrapSettings(weight_range=bad)




def test_models_are_auto_plus_the_registry():
    assert MODELS == ("auto", *MODEL_REGISTRY)
    assert set(choices_of(WrapSettings, "model")) == set(MODELS)
    with pytest.raises(ValueError, match="model"):
        WrapSettings(model="grpah")


def test_every_registry_entry_is_complete():
    for name, spec in MODEL_REGISTRY.items():
        assert spec.name == name
        if spec.fitted_by_icp:
            assert spec.build is not None and spec.schedule is not None, name
        if spec.coarse is not None:
            assert MODEL_REGISTRY[spec.coarse].build is not None, name
    assert model_spec("hybrid").needs_blendshapes and model_spec("hybrid").uses_graph
    assert not model_spec("rbf").fitted_by_icp
    with pytest.raises(ValueError, match="model must be one of"):
        model_spec("nope")
