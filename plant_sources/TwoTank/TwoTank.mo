within;
model TwoTank
  "Nonlinear two-tank level process (paper eq. 24); levels never go negative"
  // Same equations as model.c. Units: cm, cm2, cm3/s. An empty tank cannot drain: a level <= 0
  // whose rate would be negative has rate 0.
  parameter Real A1(unit = "cm2") = 15.52 "Cross-section of tank 1";
  parameter Real A2(unit = "cm2") = 15.52 "Cross-section of tank 2";
  parameter Real k1(unit = "cm2.5/s") = 10.74 "Valve coefficient between the tanks";
  parameter Real k2(unit = "cm2.5/s") = 7.89 "Outlet valve coefficient of tank 2";
  parameter Real h1_0(unit = "cm") = 0.0 "Initial level of tank 1";
  parameter Real h2_0(unit = "cm") = 0.0 "Initial level of tank 2";
  input Real q_in(start = 0.0, unit = "cm3/s") "Pump inflow into tank 1";
  input Real q_d(start = 0.0, unit = "cm3/s") "Inflow disturbance into tank 1";
  input Real valve_factor(start = 1.0) "Multiplies k1 (step changes in the valve characteristic)";
  output Real h1(start = h1_0, fixed = true, unit = "cm") "Level of tank 1";
  output Real h2(start = h2_0, fixed = true, unit = "cm") "Level of tank 2 (controlled)";
protected
  Real q12(unit = "cm3/s") "Flow from tank 1 into tank 2";
  Real q2(unit = "cm3/s") "Outflow of tank 2";
  Real dh1(unit = "cm/s") "Rate of h1 before the empty-tank rule";
  Real dh2(unit = "cm/s") "Rate of h2 before the empty-tank rule";
equation
  q12 = valve_factor*k1*sqrt(max(h1 - h2, 0));
  q2 = k2*sqrt(max(h2, 0));
  dh1 = (q_in + q_d - q12)/A1;
  dh2 = (q12 - q2)/A2;
  der(h1) = if h1 <= 0 and dh1 < 0 then 0 else dh1;
  der(h2) = if h2 <= 0 and dh2 < 0 then 0 else dh2;
end TwoTank;
