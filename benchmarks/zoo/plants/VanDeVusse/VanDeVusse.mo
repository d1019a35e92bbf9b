within;
model VanDeVusse "Isothermal Van de Vusse CSTR, A -> B -> C, 2A -> D (Engell & Klatt 1993; Bequette 2003)"
  // Same equations as model.c; rates per minute, time in s. Starts at the steady state of D = 4/7 1/min.
  parameter Real k1(unit = "1/min") = 5 / 6;
  parameter Real k2(unit = "1/min") = 5 / 3;
  parameter Real k3 = 1 / 6 "L/(mol min)";
  parameter Real Caf(unit = "mol/L") = 10;
  input Real D(unit = "1/min", start = 4 / 7) "Dilution rate";
  output Real Cb(unit = "mol/L", start = 1.1170212765957446, fixed = true);
  output Real Ca(unit = "mol/L", start = 3.0, fixed = true);
equation
  der(Ca) = (D * (Caf - Ca) - k1 * Ca - k3 * Ca^2) / 60;
  der(Cb) = (-D * Cb + k1 * Ca - k2 * Cb) / 60;
end VanDeVusse;
