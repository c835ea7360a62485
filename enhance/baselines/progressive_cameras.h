// The novel cameras of Difix3D's progressive 3D update (nv-tlabs/Difix3D examples/utils.py,
// CameraPoseInterpolator, as its trainers call it with distance 0.5 and unit weights): each round
// every target camera's current pose moves a fixed step towards it, the 3DGS is re-rendered there,
// enhanced, and fine-tuned on (docs/baselines.md).
//
// Poses are camera-to-world (the centre c and the rotation Rc = R^T of our world-to-camera R):
//   distance(a, b) = |c_a - c_b| + angle(a, b),  angle = arccos(2 <q_a, q_b>^2 - 1), the geodesic
//                    angle between the rotations (radians; metres and radians simply added)
//   nearest(target, poses) = argmin distance (first on ties), each target on its own
//   shift(S, T, step): if distance(S, T) <= step, T itself. Else the centre moves `step` along the
//                    straight line to T's (to T's if at most `step` would be left, or if the
//                    centres coincide within 1e-6); the rotation is slerp(q_S, q_T, min(step / |c_T
//                    - c_S|, 1)) (q_T itself when the centres coincide) - so the rotation advances
//                    with the translation, and a rotation-only gap snaps at once.
// Intrinsics and size of the novel camera: `intrinsics` (Difix3D: the first training camera's).
//
// A round: targets[i] moves from current[nearest(targets[i], current)], where current is every
// training camera in the first round and the previous round's novel poses after that.
#pragma once

#include <string>
#include <vector>

#include "gs/cameras/camera.h"

namespace macro::enhance {

double pose_distance(const gs::Camera& a, const gs::Camera& b);
// The index in `poses` of the pose nearest to `target`; -1 when poses is empty.
int nearest_pose(const gs::Camera& target, const std::vector<gs::Camera>& poses);
// The pose `step` from `from` towards `target` (see above), with the intrinsics and size of
// `intrinsics` and the name `name`.
gs::Camera shift_pose(const gs::Camera& from, const gs::Camera& target, double step,
                      const gs::Camera& intrinsics, const std::string& name);

// Every round's novel cameras for the targets, rounds 1..rounds: round r's i-th camera is named
// "<target name>@r". Each target stays at itself once reached.
std::vector<std::vector<gs::Camera>> progressive_schedule(const std::vector<gs::Camera>& training,
                                                          const std::vector<gs::Camera>& targets,
                                                          int rounds, double step = 0.5);

}  // namespace macro::enhance
