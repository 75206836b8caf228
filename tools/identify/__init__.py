"""armctl identify: the excitation, the fit and the identified arm file."""
