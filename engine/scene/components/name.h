#pragma once
#include <string>

namespace specula {

/// A human-readable name (scene files, editor, error messages). Not required to be unique.
struct Name {
  std::string value;
};

} // namespace specula
