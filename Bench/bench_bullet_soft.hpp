// Bullet soft bodies as the physics benchmarks step them: position-based link
// projection only, stepped directly (what btSoftRigidDynamicsWorld does per
// soft body, minus broadphase and rigid contacts, of which there are none).
#pragma once

#include <BulletSoftBody/btSoftBody.h>

namespace dm::bench {

/// `piterations` position-solver sweeps over the links a step; no velocity,
/// drift or cluster iterations and no damping.
inline void usePositionSolverOnly(btSoftBody& sb, int piterations) {
  sb.m_cfg.piterations = piterations;
  sb.m_cfg.viterations = 0;
  sb.m_cfg.diterations = 0;
  sb.m_cfg.citerations = 0;
  sb.m_cfg.kDP = 0;
}

/// One step of h seconds: predict, solve the links, integrate.
inline void stepSoftBody(btSoftBody& sb, double h) {
  sb.predictMotion(btScalar(h));
  sb.solveConstraints();
  sb.integrateMotion();
}

}  // namespace dm::bench
