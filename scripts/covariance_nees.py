"""The published pose covariances against ground truth, computed independently of mrsmap
(Python mcap + mcap-ros2-support readers, scipy rotations and slerp): the median NEES
of the replay's PoseWithCovarianceStamped messages, per pose and per change between
consecutive frames, as `mrsmap replay --groundtruth` prints them (docs/evaluation.md,
"The pose covariance").

    python3 scripts/covariance_nees.py poses.mcap groundtruth.txt TOPIC tx ty tz qx qy qz qw

TOPIC is the object's pose topic (/mrsmap/<object>/pose); the seven numbers are the
model's world_from_model (`mrsmap model info` prints them). Held poses (identity
covariance) are skipped, as the tracker marks them. Needs
`pip install mcap mcap-ros2-support scipy numpy`.
"""
import sys, numpy as np
from mcap_ros2.reader import read_ros2_messages
from scipy.spatial.transform import Rotation as R, Slerp

if len(sys.argv) != 11:
    sys.exit(__doc__)
mcap_path, gt_path, topic = sys.argv[1], sys.argv[2], sys.argv[3]
w = [float(v) for v in sys.argv[4:11]]
w_t = np.array(w[:3]); w_q = w[3:]
world_from_model = (R.from_quat(w_q), w_t)
gt = np.array([[float(v) for v in l.split()] for l in open(gt_path) if not l.startswith('#') and l.strip()])
def gt_at(t):
    i = np.searchsorted(gt[:, 0], t)
    if i == 0 or i >= len(gt): return None
    a, b = gt[i - 1], gt[i]
    if t - a[0] > 0.05 or b[0] - t > 0.05: return None
    s = (t - a[0]) / (b[0] - a[0])
    tr = a[1:4] + s * (b[1:4] - a[1:4])
    rot = Slerp([0, 1], R.from_quat([a[4:8], b[4:8]]))([s])[0]
    return rot, tr
errors = []
for k, m in enumerate(read_ros2_messages(mcap_path, topics=[topic])):
    msg = m.ros_msg
    cov = np.array(msg.pose.covariance).reshape(6, 6)
    if np.allclose(cov, np.eye(6)): continue  # held pose: no covariance
    t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    g = gt_at(t)
    if g is None: continue
    (rw, tw) = world_from_model
    # object_from_camera (truth) = model_from_world * world_from_camera
    rwc, twc = g
    r_oc = rw.inv() * rwc; t_oc = rw.inv().apply(twc - tw)
    # camera_from_object (truth)
    r_co = r_oc.inv(); t_co = -r_co.apply(t_oc)
    p = msg.pose.pose.position; q = msg.pose.pose.orientation
    r_est = R.from_quat([q.x, q.y, q.z, q.w]); t_est = np.array([p.x, p.y, p.z])
    e = np.concatenate([t_co - t_est, (r_co * r_est.inv()).as_rotvec()])
    errors.append((k, e, cov))
nees = lambda e, c: float(e @ np.linalg.solve(c, e))
absolute = [nees(e, c) for _, e, c in errors]
changes = [nees(b[1] - a[1], a[2] + b[2]) for a, b in zip(errors, errors[1:]) if b[0] == a[0] + 1]
print(f"absolute: {len(absolute)} poses, median NEES {np.median(absolute):.1f}")
print(f"frame to frame: {len(changes)} changes, median NEES {np.median(changes):.1f}")
