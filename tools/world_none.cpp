// A build without MPI: every process is a job of its own.
#include "tools/world.hpp"

#include <string>

namespace tetstream::cli {

using pipeline::Communicator;
using pipeline::launcher_size;
using pipeline::single_process;

bool mpi_built() { return false; }

Communicator& world() { return single_process(); }

WorldSession::WorldSession(int&, char**&) {
  if (const int n = launcher_size(); n > 1)
    throw UsageError("started as " + std::to_string(n) +
                     " MPI processes, but this tetstream was built without MPI (install libopenmpi-dev and rebuild "
                     "with -DTETSTREAM_MPI=ON)");
}

WorldSession::~WorldSession() = default;

}  // namespace tetstream::cli
