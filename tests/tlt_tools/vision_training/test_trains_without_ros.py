"""The lent GPU machines that train Mask R-CNN have torch and no ROS: rendering a training set and
training with validation as the node segments (``--node-config``) must not import rclpy or any ROS
message package. A module-level ROS import on that path fails the training run only on the lent
machine, after its minutes have started counting, so it is caught here."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

# Run in a fresh interpreter: this one has imported ROS already through other tests.
PROBE = """
import sys

class NoRos:
    roots = {"rclpy", "rosidl_parser", "sensor_msgs", "std_msgs", "geometry_msgs", "builtin_interfaces",
             "action_msgs", "tlt_interfaces", "py_trees_ros", "mcap_ros2"}

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in self.roots:
            raise ImportError(f"{name} imported on the training path")
        return None

sys.meta_path.insert(0, NoRos())

import tlt_tools.vision_training.render_dataset
from tlt_vision.segmentation.config import MaskRCNNConfig
from tlt_vision.segmentation.model import MaskRCNN
from tlt_tools.vision_training.mask_rcnn import node_segmenter

node_segmenter("config/vision/node.yaml", MaskRCNN(MaskRCNNConfig()), None)
print("ok")
"""


def test_render_and_node_validation_import_no_ros() -> None:
    env_path = f"{ROOT / 'src'}:{ROOT / 'sim'}:{ROOT / 'tools'}"
    done = subprocess.run(
        [sys.executable, "-c", PROBE],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={"PYTHONPATH": env_path, "PATH": "/usr/bin:/bin", "HOME": "/tmp"},
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().endswith("ok")
