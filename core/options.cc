#include "core/options.h"

#include <algorithm>
#include <numeric>

namespace raytime {

int EditDistance(const std::string& a, const std::string& b) {
  std::vector<int> row(b.size() + 1);
  std::iota(row.begin(), row.end(), 0);
  for (size_t i = 1; i <= a.size(); ++i) {
    int diagonal = row[0];
    row[0] = static_cast<int>(i);
    for (size_t j = 1; j <= b.size(); ++j) {
      const int above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

std::string NearestKey(const std::string& key, const std::vector<std::string>& candidates) {
  std::string best;
  int best_distance = static_cast<int>(key.size()) / 2 + 1;
  for (const auto& candidate : candidates) {
    const int d = EditDistance(key, candidate);
    if (d < best_distance) {
      best_distance = d;
      best = candidate;
    }
  }
  return best;
}

std::string UnknownKeyMessage(const std::string& what, const std::string& key,
                              const std::vector<std::string>& candidates,
                              const std::string& noun) {
  std::string message = "unknown " + noun + " '" + key + "' in " + what;
  const std::string nearest = NearestKey(key, candidates);
  if (!nearest.empty()) message += " (did you mean '" + nearest + "'?)";
  message += "; valid " + noun + "s: ";
  for (size_t i = 0; i < candidates.size(); ++i) message += (i ? ", " : "") + candidates[i];
  return message;
}

int YamlLine(const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  return mark.line >= 0 ? mark.line + 1 : 0;
}

}  // namespace raytime
