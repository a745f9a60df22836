#include "core/graph.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>

namespace raytime {
namespace {

void CheckEdges(int num_nodes, const std::vector<std::pair<int, int>>& edges) {
  for (const auto& [a, b] : edges) {
    if (a < 0 || b < 0 || a >= num_nodes || b >= num_nodes) {
      throw std::invalid_argument("graph edge (" + std::to_string(a) + ", " + std::to_string(b) +
                                  ") out of range for " + std::to_string(num_nodes) + " nodes");
    }
  }
}

}  // namespace

UnionFind::UnionFind(int n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0); }

int UnionFind::Find(int x) {
  while (parent_[x] != x) {
    parent_[x] = parent_[parent_[x]];
    x = parent_[x];
  }
  return x;
}

bool UnionFind::Union(int a, int b) {
  a = Find(a);
  b = Find(b);
  if (a == b) return false;
  if (b < a) std::swap(a, b);
  parent_[b] = a;
  return true;
}

std::vector<int> ConnectedComponents(int num_nodes, const std::vector<std::pair<int, int>>& edges) {
  CheckEdges(num_nodes, edges);
  UnionFind sets(num_nodes);
  for (const auto& [a, b] : edges) sets.Union(a, b);
  std::vector<int> root(num_nodes), size(num_nodes, 0);
  for (int i = 0; i < num_nodes; ++i) {
    root[i] = sets.Find(i);
    ++size[root[i]];
  }
  // Roots are the smallest node of their set (Union keeps the smaller index), so sorting roots
  // by (size desc, root asc) orders components by size with ties to the smaller node index.
  std::vector<int> roots;
  for (int i = 0; i < num_nodes; ++i) {
    if (root[i] == i) roots.push_back(i);
  }
  std::stable_sort(roots.begin(), roots.end(), [&](int a, int b) { return size[a] > size[b]; });
  std::vector<int> label_of_root(num_nodes, -1);
  for (size_t k = 0; k < roots.size(); ++k) label_of_root[roots[k]] = static_cast<int>(k);
  std::vector<int> labels(num_nodes);
  for (int i = 0; i < num_nodes; ++i) labels[i] = label_of_root[root[i]];
  return labels;
}

std::vector<int> MaximumSpanningForest(int num_nodes, const std::vector<std::pair<int, int>>& edges,
                                       const std::vector<double>& weights) {
  CheckEdges(num_nodes, edges);
  if (weights.size() != edges.size()) {
    throw std::invalid_argument("MaximumSpanningForest: one weight per edge expected");
  }
  std::vector<int> order(edges.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return weights[a] > weights[b]; });
  UnionFind sets(num_nodes);
  std::vector<int> chosen;
  for (int e : order) {
    if (sets.Union(edges[e].first, edges[e].second)) chosen.push_back(e);
  }
  return chosen;
}

}  // namespace raytime
