// The registry of contact laws: the one list of laws and the only switch on ContactModel.
//
// A law is a type with static members (laws/linear.hpp documents them): its model and scene
// name, whether it keeps bond state, the family constants, the per-contact constants at
// creation, the update of one contact, the idle test, the stiffness for the critical step,
// the stored energy, the force and moment for output, bond installation and its lane kernel.
// World instantiates its passes on the law type through visit_law, so no contact loop
// branches on the model. Adding a law: its header, a row here, an enum value in params.hpp; its own
// scene keys are its params() table (params.hpp "Parameter tables").
#pragma once

#include <string_view>

#include "demfdm/dem/laws/hertz.hpp"
#include "demfdm/dem/laws/linear.hpp"
#include "demfdm/dem/laws/pbond.hpp"
#include "demfdm/dem/laws/softbond.hpp"

namespace demfdm::dem {

/// Call f(Law{}) with the registered law type of model m.
template <class F>
decltype(auto) visit_law(ContactModel m, F&& f) {
  switch (m) {
    case ContactModel::kLinear: return f(LinearLaw{});
    case ContactModel::kLinearPBond: return f(PBondLaw{});
    case ContactModel::kSoftBond: return f(SoftBondLaw{});
    case ContactModel::kHertz: return f(HertzLaw{});
  }
  throw std::invalid_argument("unknown contact model");
}

/// The law type of a model known at compile time.
template <ContactModel M> struct LawOf;
template <> struct LawOf<ContactModel::kLinear> { using type = LinearLaw; };
template <> struct LawOf<ContactModel::kLinearPBond> { using type = PBondLaw; };
template <> struct LawOf<ContactModel::kSoftBond> { using type = SoftBondLaw; };
template <> struct LawOf<ContactModel::kHertz> { using type = HertzLaw; };

/// Every registered model, in enum order.
inline constexpr ContactModel kAllModels[] = {ContactModel::kLinear, ContactModel::kLinearPBond,
                                              ContactModel::kSoftBond, ContactModel::kHertz};

/// Call f(Law{}) with every registered law type, in enum order.
template <class F>
void for_each_law(F&& f) {
  for (ContactModel m : kAllModels) visit_law(m, f);
}

/// The scene name of a model ("linear", "pbond", "softbond", "hertz").
inline const char* law_name(ContactModel m) {
  return visit_law(m, [](auto law) { return decltype(law)::kName; });
}

/// The model of a scene name; false when no law has that name.
inline bool law_from_name(std::string_view name, ContactModel& m) {
  for (ContactModel c : kAllModels)
    if (name == law_name(c)) { m = c; return true; }
  return false;
}

/// Whether contacts of model m keep bond state (BondHist storage).
inline bool law_has_bond(ContactModel m) {
  return visit_law(m, [](auto law) { return decltype(law)::kBond; });
}

/// Full law of one contact for model M (kept for the unit tests that call a law by its model).
template <ContactModel M>
[[gnu::always_inline]] inline Vec3 contact_law(const Kin& k, ContactHist& h, BondHist* b, const LawConst& c, Vec3& Mo) {
  return LawOf<M>::type::update(k, h, b, c, Mo);
}

}  // namespace demfdm::dem
