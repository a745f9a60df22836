// Graph utilities shared by the stages: disjoint sets, connected components, spanning forests.
// Deterministic: results depend on node and edge indices, never on hash order or threads.
#pragma once

#include <utility>
#include <vector>

namespace raytime {

// Disjoint sets with path halving. Union keeps the smaller root, so every set's root is its
// smallest element (the anchored layout's anchors, the components' order rely on it).
class UnionFind {
 public:
  explicit UnionFind(int n);
  int Find(int x);
  // False when a and b were already in one set.
  bool Union(int a, int b);

 private:
  std::vector<int> parent_;
};

// Component label per node; labels are numbered by decreasing component size (0 = largest; ties
// go to the component holding the smaller node index), so results do not depend on edge order.
// std::invalid_argument on an edge out of range.
std::vector<int> ConnectedComponents(int num_nodes, const std::vector<std::pair<int, int>>& edges);

// Maximum spanning forest (Kruskal): indices into `edges` of the chosen edges. Ties between equal
// weights are broken by edge index, so the tree is deterministic.
std::vector<int> MaximumSpanningForest(int num_nodes, const std::vector<std::pair<int, int>>& edges,
                                       const std::vector<double>& weights);

// One cut of a minimum cut tree: the nodes of one side (ascending) and the number of edges across
// (parallel edges count each).
struct MinimumCut {
  std::vector<int> side;
  int num_edges_across = 0;
};

// The n - 1 cuts of a Gomory–Hu tree of an undirected graph whose edges count one each
// (Gusfield's algorithm: n - 1 maximum flows, no contractions): for every pair of nodes, the
// fewest edges any cut separating them has is the smallest count among these cuts that separate
// them, so the graph's weakest places are all here. Deterministic; a disconnected graph gives
// cuts of 0 edges around its components. std::invalid_argument on an edge out of range.
std::vector<MinimumCut> MinimumCutTree(int num_nodes,
                                       const std::vector<std::pair<int, int>>& edges);

}  // namespace raytime
