// Contact state and every registered contact law (docs/theory.md §1.4–1.9, §2, §3): a
// convenience header. The state is in contact_state.hpp, each law in laws/<name>.hpp, the list
// of laws and the only switch on the model in laws/registry.hpp.
#pragma once

#include "demfdm/dem/contact_state.hpp"
#include "demfdm/dem/laws/registry.hpp"
