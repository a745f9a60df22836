#include "bootstrap/view_graph.h"

namespace raytime {

const char* PairStatusName(PairStatus status) {
  switch (status) {
    case PairStatus::kValid:
      return "valid";
    case PairStatus::kPureRotation:
      return "pure_rotation";
    case PairStatus::kTooFewInliers:
      return "too_few_inliers";
    case PairStatus::kFailed:
      return "failed";
  }
  return "unknown";
}

}  // namespace raytime
