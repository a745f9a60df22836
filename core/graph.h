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

}  // namespace raytime
