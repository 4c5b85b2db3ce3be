// The phases of ContactModel::Step() and a tester that runs them one at a
// time and reads what each produced (tests only; an internal header of the
// room, as sparse_lu.hpp is).
#pragma once

#include <Eigen/Core>

#include "arena/mechanics/model.hpp"

namespace arena::mechanics {

// In the order Step() runs them (model.cpp, "One step in named phases").
enum class StepPhase {
  kPlaceContacts,  // contact points, normals, friction directions, gaps, rows this step
  kMassMatrix,     // reduced mass matrix and its inverse, the twist in reduced coordinates
  kFreeMotion,     // known wrench (gravity, known normal forces); the twist it alone gives;
                   // refuses a non-finite one (StepFailure::kNonFinite)
  kGraspMap,       // grasp map columns per force unknown, M⁻¹ J
  kContactRows,    // LCP rows of the force unknowns (normals, friction edges), force block
  kConeRows,       // LCP rows of the friction cones (ξ)
  kPadRows,        // LCP rows of the force-controlled pads (y±)
  kSupportRows,    // LCP rows of the support's limit-surface directions and its ξ
  kSolve,          // Lemke (warm, then cold retries), forces and new twist, residuals
  kCheckValues,    // refuses non-finite forces, twist or pose (StepFailure::kNonFinite)
  kContactStates,  // contact states and modes, the pusher's force
  kIntegrate,      // pads, gaps, pose and time advanced
};
inline constexpr int kStepPhases = static_cast<int>(StepPhase::kIntegrate) + 1;

class ContactModelTester {
 public:
  explicit ContactModelTester(ContactModel& model) : model_(model) {}

  // Starts a step (false, with rep's error, when the model cannot step) and
  // runs its phases, one per call, in StepPhase order. Returns false when the
  // phase refused the step (rep says why).
  bool BeginStep(StepReport& rep);
  bool Run(StepPhase phase, StepReport& rep);

  // What the phases produced (reduced coordinates: 3 planar, else 6).
  int reduced_coordinates() const;
  int force_unknowns() const;
  int lcp_size() const;
  Eigen::MatrixXd mass_matrix() const;            // kMassMatrix
  Eigen::VectorXd known_wrench() const;           // kFreeMotion (reduced)
  Eigen::VectorXd free_twist() const;             // kFreeMotion (reduced)
  Eigen::MatrixXd grasp_map() const;              // kGraspMap (reduced x force unknowns)
  Eigen::MatrixXd lcp_matrix() const;             // kSolve (formed by then; nondimensional)
  Eigen::VectorXd lcp_vector() const;             // the row phases
  Eigen::VectorXd forces() const;                 // kSolve (N)
  Eigen::Matrix<double, 6, 1> new_twist() const;  // kSolve: (v, ω) of the step's end

  // Faults: sets the object's twist as if a step had ended with it (for
  // the bad-value checks).
  void SetTwist(const Eigen::Vector3d& v, const Eigen::Vector3d& w);

 private:
  ContactModel& model_;
};

}  // namespace arena::mechanics
