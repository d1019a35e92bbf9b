within;
model SphericalTank "Level of a spherical tank with gravity outflow (Nithya et al. 2008)"
  // Same equations as model.c: A(h) dh/dt = q_in - k sqrt(h), A(h) = pi h (2R - h) floored at A_min; q in L/s.
  parameter Real R(unit = "m") = 0.5 "Radius of the sphere";
  parameter Real k = 1.4142135623730951 "Outflow coefficient, L/s per sqrt(m)";
  parameter Real A_min(unit = "m2") = 0.005 "Least cross-section";
  input Real q_in(start = 1.0) "Inflow, L/s";
  output Real h(unit = "m", start = 0.5, fixed = true) "Level";
equation
  der(h) = if h >= 2 * R and q_in > k * sqrt(h) then 0
           else (q_in - k * sqrt(max(h, 0))) / 1000 / max(Modelica.Constants.pi * h * (2 * R - h), A_min);
end SphericalTank;
