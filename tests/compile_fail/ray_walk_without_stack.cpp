// Must NOT compile: a ray walk with no stack to keep the far children on.
#include "lwsccd/traversal/ray_task.hpp"
lwsccd::RayWalkTask<0> task;
int main() {}
