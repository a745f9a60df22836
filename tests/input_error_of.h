// The message of the InputError a call throws, for tests of what a user is told.
#pragma once

#include <string>

#include "core/error.h"

namespace raytime {

// The message of the InputError `call` throws, "" when it throws none (a test that expects one
// checks the message, which "" fails; one that expects none checks for "").
template <typename Call>
std::string InputErrorOf(Call&& call) {
  try {
    call();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace raytime
