#include "core/types.h"

#include <algorithm>
#include <cctype>
#include <set>
#include <string_view>

#include "core/error.h"

namespace raytime {

int ImageSet::Find(const std::string& name) const {
  for (size_t i = 0; i < images.size(); ++i) {
    if (images[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

PoseRole PoseRoleFromName(const std::string& name) {
  PoseRole role = PoseRole::kPrior;
  if (EnumFromName(name, &role)) return role;
  throw InputError("unknown pose role '" + name + "' (expected ground_truth, prior or refined)");
}

NameJoin JoinNames(const std::vector<std::string>& left, const std::vector<std::string>& right) {
  const std::set<std::string> l(left.begin(), left.end()), r(right.begin(), right.end());
  NameJoin join;
  std::set_intersection(l.begin(), l.end(), r.begin(), r.end(), std::back_inserter(join.both));
  std::set_difference(l.begin(), l.end(), r.begin(), r.end(), std::back_inserter(join.only_left));
  std::set_difference(r.begin(), r.end(), l.begin(), l.end(), std::back_inserter(join.only_right));
  return join;
}

namespace {
std::string FirstNames(const std::vector<std::string>& names) {
  std::string out;
  for (size_t i = 0; i < names.size() && i < 5; ++i) out += (i ? ", " : "") + names[i];
  if (names.size() > 5) out += ", ...";
  return out;
}
}  // namespace

std::string NameJoin::Describe(const std::string& left, const std::string& right) const {
  std::string out;
  if (!only_left.empty()) {
    out += std::to_string(only_left.size()) + " name(s) only in " + left + ": " +
           FirstNames(only_left);
  }
  if (!only_right.empty()) {
    if (!out.empty()) out += "; ";
    out += std::to_string(only_right.size()) + " name(s) only in " + right + ": " +
           FirstNames(only_right);
  }
  return out;
}

std::vector<std::string> Names(const PoseSet& poses) {
  std::vector<std::string> names;
  for (const auto& [name, pose] : poses.world_from_cam) names.push_back(name);
  return names;
}

std::vector<std::string> Names(const ImageSet& images) {
  std::vector<std::string> names;
  for (const auto& image : images.images) names.push_back(image.name);
  return names;
}

bool NaturalNameLess(const std::string& a, const std::string& b) {
  const auto digit = [](char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; };
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (digit(a[i]) && digit(b[j])) {
      size_t i_end = i, j_end = j;
      while (i_end < a.size() && digit(a[i_end])) ++i_end;
      while (j_end < b.size() && digit(b[j_end])) ++j_end;
      // Compare the runs as numbers without overflow: strip leading zeros, then length, then text.
      size_t i_lead = i, j_lead = j;
      while (i_lead + 1 < i_end && a[i_lead] == '0') ++i_lead;
      while (j_lead + 1 < j_end && b[j_lead] == '0') ++j_lead;
      const std::string_view x(a.data() + i_lead, i_end - i_lead);
      const std::string_view y(b.data() + j_lead, j_end - j_lead);
      if (x.size() != y.size()) return x.size() < y.size();
      if (x != y) return x < y;
      i = i_end;
      j = j_end;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  if ((a.size() - i) != (b.size() - j)) return a.size() - i < b.size() - j;
  return a < b;
}

}  // namespace raytime
