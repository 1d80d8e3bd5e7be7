#include "pipeline/files/external_sort.hpp"

#include <omp.h>

namespace tetstream::pipeline::detail {

int max_threads() { return omp_get_max_threads(); }
bool in_parallel() { return omp_in_parallel() != 0; }
int team_size() { return omp_get_num_threads(); }
int thread_id() { return omp_get_thread_num(); }

}  // namespace tetstream::pipeline::detail
