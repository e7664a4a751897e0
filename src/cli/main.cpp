#include <cstdio>
int main() { std::puts("vnr"); return 0; }
