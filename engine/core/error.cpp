#include "specula/core/error.h"

#include <utility>

namespace specula {

Error::Error(const std::string& message) : std::runtime_error(message), message_(message) {}

Error::Error(std::string file, const std::string& message)
    : std::runtime_error(file + ": " + message), file_(std::move(file)), message_(message) {}

Error::Error(std::string file, int line, const std::string& message)
    : std::runtime_error(file + ":" + std::to_string(line) + ": " + message), file_(std::move(file)),
      message_(message), line_(line) {}

Error::Error(std::string file, std::string field, const std::string& message)
    : std::runtime_error(file + ": " + field + ": " + message), file_(std::move(file)),
      field_(std::move(field)), message_(message) {}

} // namespace specula
