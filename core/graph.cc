#include "core/graph.h"

#include <algorithm>
#include <numeric>
#include <queue>
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

namespace {

// Unit-capacity undirected graph as paired arcs (arc a and a ^ 1 are one edge's two directions),
// for the augmenting-path maximum flows of MinimumCutTree.
class UnitFlowGraph {
 public:
  UnitFlowGraph(int num_nodes, const std::vector<std::pair<int, int>>& edges)
      : head_(2 * edges.size()), arcs_of_(num_nodes), flow_(2 * edges.size(), 0) {
    for (size_t e = 0; e < edges.size(); ++e) {
      head_[2 * e] = edges[e].second;
      head_[2 * e + 1] = edges[e].first;
      arcs_of_[edges[e].first].push_back(static_cast<int>(2 * e));
      arcs_of_[edges[e].second].push_back(static_cast<int>(2 * e + 1));
    }
  }

  // Maximum s–t flow (from zero), then the nodes reachable from s in the residual graph: a
  // minimum cut's s side (as a mask) and its value.
  int MinimumCut(int s, int t, std::vector<bool>* s_side) {
    std::fill(flow_.begin(), flow_.end(), 0);
    int value = 0;
    std::vector<int> arc_into(arcs_of_.size());
    while (true) {
      Reach(s, &arc_into, s_side);
      if (!(*s_side)[t]) return value;
      for (int node = t; node != s; node = head_[arc_into[node] ^ 1]) {
        ++flow_[arc_into[node]];
        --flow_[arc_into[node] ^ 1];
      }
      ++value;
    }
  }

 private:
  // Breadth-first search from s over arcs with residual capacity (1 - flow); *reached marks the
  // nodes found, (*arc_into)[node] the arc that found it.
  void Reach(int s, std::vector<int>* arc_into, std::vector<bool>* reached) const {
    reached->assign(arcs_of_.size(), false);
    std::queue<int> queue;
    (*reached)[s] = true;
    queue.push(s);
    while (!queue.empty()) {
      const int node = queue.front();
      queue.pop();
      for (const int arc : arcs_of_[node]) {
        const int next = head_[arc];
        if ((*reached)[next] || flow_[arc] >= 1) continue;
        (*reached)[next] = true;
        (*arc_into)[next] = arc;
        queue.push(next);
      }
    }
  }

  std::vector<int> head_;                  // arc -> node it points to
  std::vector<std::vector<int>> arcs_of_;  // node -> arcs leaving it
  std::vector<int> flow_;                  // per arc, -1, 0 or 1 (antisymmetric per edge)
};

}  // namespace

std::vector<MinimumCut> MinimumCutTree(int num_nodes,
                                       const std::vector<std::pair<int, int>>& edges) {
  CheckEdges(num_nodes, edges);
  UnitFlowGraph graph(num_nodes, edges);
  // Gusfield's Gomory–Hu tree: node s hangs from parent[s] by an edge of value[s], the minimum
  // s–parent cut; the swap below keeps the tree cut-equivalent (removing its edge (s, parent[s])
  // leaves s's subtree as a minimum cut's side), not just flow-equivalent.
  std::vector<int> parent(num_nodes, 0);
  std::vector<int> value(num_nodes, 0);
  std::vector<bool> side;
  for (int s = 1; s < num_nodes; ++s) {
    const int t = parent[s];
    value[s] = graph.MinimumCut(s, t, &side);
    for (int node = 0; node < num_nodes; ++node) {
      if (node != s && side[node] && parent[node] == t) parent[node] = s;
    }
    if (side[parent[t]]) {
      parent[s] = parent[t];
      parent[t] = s;
      std::swap(value[s], value[t]);
    }
  }
  // Each tree edge's side: s's subtree.
  std::vector<std::vector<int>> children(num_nodes);
  for (int node = 1; node < num_nodes; ++node) children[parent[node]].push_back(node);
  std::vector<MinimumCut> cuts;
  for (int s = 1; s < num_nodes; ++s) {
    MinimumCut cut;
    cut.num_edges_across = value[s];
    std::vector<int> stack{s};
    while (!stack.empty()) {
      const int node = stack.back();
      stack.pop_back();
      cut.side.push_back(node);
      stack.insert(stack.end(), children[node].begin(), children[node].end());
    }
    std::sort(cut.side.begin(), cut.side.end());
    cuts.push_back(std::move(cut));
  }
  return cuts;
}

}  // namespace raytime
