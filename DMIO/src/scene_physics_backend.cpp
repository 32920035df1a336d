// scene_physics_backend.cpp — the physics engine's "backend" (v2): the
// built-in contact solver or the Open Dynamics Engine, with ODE's settings
// under "ode" (docs/scene-format.md, "Physics backends"; the runtime builds
// a dm::OdeWorld in DMEngine/src/physics_engine.cpp).
#include "scene_parse.hpp"

namespace dm::scene_parse {

void readPhysicsBackend(ConfigReader& physics, ScenePhysicsEngine& p) {
  using Backend = ScenePhysicsEngine::Backend;
  const std::size_t before = physics.errors().size();
  const std::string backend = physics.oneOf("backend", {"builtin", "ode"}, "builtin");
  if (physics.errors().size() != before) return;
  p.backend = backend == "ode" ? Backend::Ode : Backend::BuiltIn;
  if (p.backend == Backend::Ode && p.sleep)
    physics.addError("the ODE backend has no sleeping bodies", "sleep",
                     "remove \"sleep\" or use \"backend\": \"builtin\"");
  if (!physics.has("ode")) return;
  if (p.backend != Backend::Ode) {
    physics.addError("ODE settings, but the backend is the built-in solver", "ode",
                     "set \"backend\": \"ode\" or remove \"ode\"");
    return;
  }
  ConfigReader r = physics.child("ode");
  if (!expectObject(r)) return;
  r.knownKeys({"iterations", "erp", "cfm", "contacts_per_pair", "surface_layer"});
  ScenePhysicsEngine::Ode& o = p.ode;
  o.iterations = static_cast<int>(r.integer("iterations", {.min = 1, .max = 1000}, o.iterations));
  const std::size_t b = r.errors().size();
  o.erp = r.number("erp", {.min = 0.0, .max = 1.0}, o.erp);
  if (r.errors().size() == b && !(o.erp > 0.0))
    r.addError("erp is 0: ODE would never correct a joint's or contact's error", "erp",
               "give a value in (0, 1]; 0.2 is typical");
  o.cfm = r.number("cfm", {.min = 0.0, .max = 1.0}, o.cfm);
  o.contactsPerPair =
      static_cast<int>(r.integer("contacts_per_pair", {.min = 1, .max = 64}, o.contactsPerPair));
  o.surfaceLayer = r.number("surface_layer", {.min = 0.0, .max = 0.01}, o.surfaceLayer);
}

void writePhysicsBackend(const ScenePhysicsEngine& p, Json& physics) {
  if (p.backend != ScenePhysicsEngine::Backend::Ode) return;
  physics["backend"] = "ode";
  physics["ode"] = {{"iterations", p.ode.iterations},
                    {"erp", p.ode.erp},
                    {"cfm", p.ode.cfm},
                    {"contacts_per_pair", p.ode.contactsPerPair},
                    {"surface_layer", p.ode.surfaceLayer}};
}

}  // namespace dm::scene_parse
