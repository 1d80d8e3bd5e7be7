#include "pipeline/external_sort.hpp"

#include <omp.h>

namespace tetstream::pipeline::detail {

int max_threads() { return omp_get_max_threads(); }
bool in_parallel() { return omp_in_parallel() != 0; }

}  // namespace tetstream::pipeline::detail
