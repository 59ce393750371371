// Derivative-free minimisation of a few parameters (Nelder and Mead's simplex): for
// likelihoods whose derivatives are not at hand, such as the measured-repeatability
// analysis's variance components.
#pragma once

#include <functional>
#include <vector>

namespace mcms {

// Minimises f from x0 with a starting simplex of edge `step` along each axis, for at most
// `max_iter` iterations or until the simplex's values agree to 1e-10 (relative) and its
// vertices to 1e-7; returns the best vertex and its value in *fbest. Reflection 1,
// expansion 2, contraction 1/2, shrink 1/2. With no parameters, f(x0).
std::vector<double> NelderMead(const std::function<double(const std::vector<double>&)>& f, std::vector<double> x0,
                               double step, int max_iter, double* fbest);

}  // namespace mcms
