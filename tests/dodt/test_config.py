"""Configuration values changed by name (dodt.config.override, `--set section.field=value`)."""
import pytest

from dodt.config import DODTConfig, override
from dodt.presets import preset


def test_values_are_read_as_their_fields_types():
    cfg = override(preset("dodt"), ["kalman.q_pos=0.02", "learned.enabled=true", "learned.layout=yolov8",
                                    "learned.input_size=640,480", "identification.release_span=none",
                                    "learned.views=full,flip", "voxel.occupied_threshold=8", "name=mine"])
    assert cfg.kalman.q_pos == 0.02 and cfg.learned.enabled is True and cfg.learned.layout == "yolov8"
    assert cfg.learned.input_size == (640, 480) and cfg.identification.release_span is None
    assert cfg.learned.views == ("full", "flip") and cfg.voxel.occupied_threshold == 8 and cfg.name == "mine"
    assert preset("dodt").kalman.q_pos == 0.01  # the preset is left as it was
    assert override(DODTConfig(), []) == DODTConfig()


@pytest.mark.parametrize("text, match", [
    ("kalman", r"expected section.field=value"),
    ("x.y=1", r"no section 'x'; sections: depth, voxel"),
    ("kalman.nope=1", r"KalmanConfig has no field 'nope'"),
    ("kalman.q_pos=fast", r"kalman.q_pos=fast: expected a number"),
    ("voxel.occupied_threshold=6.5", r"expected a whole number"),
    ("learned.enabled=maybe", r"expected true or false"),
    ("learned.input_size=1,2,3", r"expected 2 comma-separated values"),
    ("a.b.c=1", r"expected section.field or a top-level field"),
    ("kalman.q_pos=none", r"expected a number"),
])
def test_bad_assignments_are_refused_by_name(text, match):
    with pytest.raises(ValueError, match=match):
        override(DODTConfig(), [text])
