// option_rules.hpp (private) — the one way DMHaptics renderers check their
// numeric options: a table of rules, the first broken one becomes an
// InvalidArgument naming "<owner>: options.<field>", the value and the rule.
#pragma once

#include <dm/core/result.hpp>

#include <array>
#include <cmath>
#include <span>
#include <string>

namespace dm::haptics_detail {

/// One option: its field name, value, whether it holds, and the rule in words.
struct OptionRule {
  const char* field;
  double value;
  bool ok;
  const char* rule;
};

/// Ok, or the first rule that does not hold, as "option F is V; it must be R"
/// at "<owner>: options.F" with the hint "fix the <optionsType> field".
inline Status checkOptionRules(std::span<const OptionRule> rules, const char* owner,
                               const char* optionsType) {
  for (const OptionRule& r : rules)
    if (!r.ok)
      return fail(ErrorCode::InvalidArgument,
                  formatString("option %s is %g; it must be %s", r.field, r.value, r.rule),
                  std::string(owner) + ": options." + r.field,
                  std::string("fix the ") + optionsType + " field");
  return ok();
}

/// The virtual-coupling gains the 6-DOF renderers share: linear and angular
/// stiffness finite and > 0, damping finite and >= 0.
inline std::array<OptionRule, 4> couplingRules(double stiffness, double damping, double angularStiffness,
                                               double angularDamping) {
  const auto finite = [](double v) { return std::isfinite(v); };
  return {{{"couplingStiffness", stiffness, finite(stiffness) && stiffness > 0, "finite and > 0 N/m"},
           {"couplingDamping", damping, finite(damping) && damping >= 0, "finite and >= 0 N*s/m"},
           {"couplingAngularStiffness", angularStiffness, finite(angularStiffness) && angularStiffness > 0,
            "finite and > 0 N*m/rad"},
           {"couplingAngularDamping", angularDamping, finite(angularDamping) && angularDamping >= 0,
            "finite and >= 0 N*m*s/rad"}}};
}

}  // namespace dm::haptics_detail
