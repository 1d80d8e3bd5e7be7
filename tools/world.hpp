#pragma once
// The processes of this run of the binary: MPI's world when an MPI launcher started it
// (and the build has MPI: tools/world_mpi.cpp), else one process (tools/world_none.cpp).
// The libraries know only pipeline::Communicator; MPI is linked into the binary alone.
#include "pipeline/util/communicator.hpp"

namespace tetstream::cli {

// The job's communicator: MPI's world under a launcher, else pipeline::single_process().
pipeline::Communicator& world();

// Owns MPI for the process (main makes one first): MPI_Init_thread when an MPI
// launcher started the process, MPI_Finalize at the end. UsageError when a launcher
// started several processes and this build has no MPI (they would all write one
// output).
class WorldSession {
 public:
  WorldSession(int& argc, char**& argv);
  ~WorldSession();
  WorldSession(const WorldSession&) = delete;
  WorldSession& operator=(const WorldSession&) = delete;
};

// Whether this build can run distributed (-DTETSTREAM_MPI found MPI).
bool mpi_built();

}  // namespace tetstream::cli
