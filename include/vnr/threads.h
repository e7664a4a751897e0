#pragma once
// The CPU threads vnr's parallel work uses (OpenMP): every front end's --threads.

namespace vnr {

int num_threads();
void set_num_threads(int n);  // n <= 0 means "all cores"

}  // namespace vnr
