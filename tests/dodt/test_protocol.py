"""dodt.protocol: the perception protocol lives in dodt/ and keeps dodt free of the simulator and planner."""
import subprocess
import sys

import numpy as np

from dodt.protocol import PerceptionModule, PerceptionOutput


def test_importing_the_protocol_pulls_in_no_other_package():
    code = ("import sys, dodt.protocol; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'sim', 'planner', 'experiments', 'pybullet'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"


def test_a_class_with_the_methods_and_flags_is_a_perception_module():
    class Nothing:
        name = "nothing"
        uses_ground_truth = uses_images = uses_color = False

        def reset(self):
            pass

        def update(self, frame, truth=None):
            return PerceptionOutput(stamp=frame.stamp, obstacles=())

    class NoUpdate:
        name = "half"
        uses_ground_truth = uses_images = uses_color = False

        def reset(self):
            pass

    assert isinstance(Nothing(), PerceptionModule) and not isinstance(NoUpdate(), PerceptionModule)
    out = PerceptionOutput(stamp=1.5, obstacles=(), clear_boxes=((np.zeros(3), np.ones(3)),))
    assert out.tracks == () and out.timings_ms == {} and out.skipped is None
