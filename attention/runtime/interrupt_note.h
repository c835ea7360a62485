// A line the SIGINT/SIGTERM handler of install_interrupt_cleanup() (file_io.h) prints after its
// own, e.g. which checkpoint a long job can resume from; "" clears it. At most 1023 bytes are
// kept. Implemented in file_io.cpp (the handler lives there).
#pragma once

#include <string>

namespace macro {

void set_interrupt_note(const std::string& note);

}  // namespace macro
