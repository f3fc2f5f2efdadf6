// facescan: the command-line client of the face scanning service (see `facescan --help`).
#include "client/commands.hpp"

int main(int argc, char** argv) { return facescan::client::facescanMain(argc, argv); }
