// The contact model of one scene, stepped in time (Simulate() drives it;
// benchmarks and tests may step it directly).
//
// Formulation (velocity-level time stepping with inertia):
//   M (v+ - v) / dt = G f + w_known          (Newton-Euler; v the object twist
//                                              in the gripper frame, which is
//                                              the inertial reference)
//   per constituent point j: a_n = n.(u_obj(p_j) - u_body(p_j)) + gap/dt >= 0 ⊥ λ_n >= 0
//   friction (Stewart-Trinkle, facets edges D inscribed in the Coulomb cone):
//     μ λ_n - eᵀβ >= 0 ⊥ ξ >= 0,   ξ e + Dᵀ u_rel >= 0 ⊥ β >= 0
//   fingers are force-controlled rigid pads with one free normal velocity v_f:
//     u_body = v_f n, Σ_j λ_nj = grip_force (equality paired with free v_f);
//     a point finger therefore has λ_n = grip_force and no normal row.
//   the pusher is velocity-controlled (virtual 6-DOF actuator, J_ext1 = I6):
//     u_body(p) = v_p + ω_p × (p - pusher contact point).
//   a support (scene.support, planar only): its limit surface as K sampled
//     friction wrenches D_k with the known load μ m g (support_stage.hpp):
//     ξ_s + D_kᵀ ν⁺ >= 0 ⊥ β_k >= 0,  μ m g - Σ β_k >= 0 ⊥ ξ_s >= 0.
// Substituting v+ leaves a mixed LCP in forces (λ, β), slacks ξ and pad
// velocities (v_f = y⁺ - y⁻); it is nondimensionalised by the scene's
// force, mass and time-step scales and solved with SolveLcp (lcp.hpp).
//
// Geometry, model.contacts = tracked (the default): every step the contact
// points, normals and gaps come from the object's current pose (closest
// features against the box, cylinder or prism; docs/scene.md, "Tracked
// contacts"); a finger point whose closing line misses the object, or a
// patch point off its edge chord, has no rows that step (unit diagonal, z =
// 0), so the LCP keeps its size; a point finger's pad is re-seated along its
// closing direction, and its friction rows see the pad's following removed.
// model.contacts = fixed (the frozen frame): fingers stay where they are in
// the gripper frame except that their pads follow the object along their
// normals; the pusher's contact points move with its motion; contact points
// on the object are taken where the contacts are, so the object slides
// under them. The gyroscopic torque
// is neglected (quasi-dynamic regime; explicit integration of it is unstable). Line constituent
// points are spread evenly over the line; patch constituent points sit on a ring of radius 2R/3
// (which gives a uniformly pressed disk's torsional friction 2/3 μ N R when the points share the
// load) starting along t1, a single point at the centre when points = 1.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arena/mechanics/frames.hpp"  // FirstTangent, RotationFromRpy (were declared here)
#include "arena/mechanics/scene.hpp"
#include "arena/mechanics/simulate.hpp"

namespace arena::mechanics {

// Unit edge directions of the inscribed polyhedral cone: angle 2πj/facets
// from t1 towards t2 = n × t1.
std::vector<Eigen::Vector3d> ConeEdges(const Eigen::Vector3d& normal, int facets);

// Constituent points of a contact as offsets from its position (gripper frame).
std::vector<Eigen::Vector3d> ConstituentOffsets(const ContactSpec& contact, int points);

// Inertia about the centre of mass in the object frame (kg m^2).
Eigen::Matrix3d ObjectInertia(const ObjectSpec& object);

// Planarity: the scene is planar when one plane (normal `normal`, through the
// object's centre of mass) contains every contact point, normal, line axis,
// gravity and pusher velocity, the pusher turns about the plane normal only,
// the plane normal is a principal axis of the object's inertia, no patch has
// more than one point, and each friction cone (when μ > 0) has edges along
// both in-plane tangents and is symmetric about the plane (so that the full
// polyhedral model produces no out-of-plane force on in-plane motion).
struct PlaneCheck {
  bool planar = false;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitY();
  std::string reason;  // why not planar
};
PlaneCheck FindPlane(const Scene& scene);

// Why a step was refused (StepReport::failure).
enum class StepFailure {
  kNone,        // the step was taken
  kModel,       // the scene cannot be modelled (ContactModel::error())
  kSolver,      // Lemke found no solution
  kInaccurate,  // every solve's physical residuals exceeded the accepted ones
  kNonFinite,   // a force, the twist or the pose came out non-finite
};

// How far the friction cones steered the slip in one step (issue 31), over
// the points that slide: the friction's size, its part across the slip
// (|f_t × û|, û the slip's direction: the circular cone's friction has none;
// a polyhedral cone's has some wherever a slip falls between two of its
// edges, and it then turns the slip towards an edge), and the largest angle
// between a friction and its slip's opposite.
struct SlipSteering {
  double sliding_friction = 0;  // N: Σ |f_t|
  double across = 0;            // N: Σ |f_t × û|
  double max_rad = 0;
};

// One step's diagnostics (nondimensional residuals, see Residuals).
struct StepReport {
  bool ok = true;
  std::string error;
  StepFailure failure = StepFailure::kNone;
  int pivots = 0;
  bool warm_start_used = false;
  int align_solves = 0;         // solves repeated to align cones with the slip
  int quasi_static_solves = 0;  // solves repeated to balance the forces
  // Quasi-static: 1 when no balanced answer was found and the step carried
  // the momentum (the object accelerates, e.g. slides out of its grasp).
  int quasi_static_carried = 0;
  Residuals residuals;
  SlipSteering steering;  // of the step's accepted answer
};

class ContactModel {
 public:
  // status() != kOk when the scene cannot be modelled (reason in error()).
  explicit ContactModel(const Scene& scene);
  ~ContactModel();
  ContactModel(const ContactModel&) = delete;
  ContactModel& operator=(const ContactModel&) = delete;

  SimulationStatus status() const;
  const std::string& error() const;
  const ModelInfo& info() const;

  // Advances the state by one dt. On failure the state is left unchanged.
  StepReport Step();

  // Called by every Step() with the step's nondimensional LCP (w = A z + b,
  // before any solve), e.g. to collect solver benchmark problems
  // (bench/lcp_solvers_bench.cpp). Empty: none (the default).
  using LcpObserver = std::function<void(const Eigen::MatrixXd& A, const Eigen::VectorXd& b)>;
  void SetLcpObserver(LcpObserver observer);

  // Closed loop: the pusher moves with `motion` from the next Step() on,
  // continuing from where it is now. Translation only: an angular velocity
  // different from the scene's is refused (returns false, nothing changed).
  bool SetPusherMotion(const PusherMotion& motion);

  double time() const;                      // s
  const Eigen::Vector3d& position() const;  // object centre of mass (m)
  Eigen::Quaterniond orientation() const;
  const Eigen::Vector3d& velocity() const;  // m/s (of the last step)
  const Eigen::Vector3d& angular_velocity() const;
  Eigen::Vector3d pusher_position() const;  // pusher contact point at time()
  // Contact states of the last step: fingers in scene order, then the pusher.
  const std::vector<ContactState>& contacts() const;
  Eigen::Vector3d pusher_force() const;  // on the object (N), last step
  double force_scale() const;            // N, residuals are relative to it
  // Whether the fingers still hold the object as the grasp began (see
  // GraspStatus); *note names the first finger that does not.
  GraspStatus Grasp(std::string* note) const;
  double velocity_scale() const;  // m/s
  double length_scale() const;    // m: the object's extent
  double gap_tolerance() const;   // m: within it a tracked contact touches (1e-4 of the extent)

 private:
  friend class ContactModelTester;  // runs and reads the step's phases (tests)
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arena::mechanics
