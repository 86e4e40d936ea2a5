// evloc-mapper: builds, imports and inspects evloc maps. See mapper/mapper_cli.h.
#include <iostream>

#include "mapper/mapper_cli.h"

int main(int argc, char** argv) { return evloc::RunMapperCli(argc, argv, std::cout, std::cerr); }
