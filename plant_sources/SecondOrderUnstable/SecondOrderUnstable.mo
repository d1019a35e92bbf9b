within;
model SecondOrderUnstable
  "Second-order unstable, non-minimum-phase plant G(s) = K(1 - Tn s)/(a2 s^2 + a1 s + a0) (paper eq. 17)"
  // Controllable canonical form of the transfer function; same equations as model.c.
  parameter Real K = -0.2679 "Numerator gain";
  parameter Real Tn(unit = "s") = 41.667 "Numerator time constant (zero at s = 1/Tn)";
  parameter Real a2(unit = "s2") = 279.03 "Denominator s^2 coefficient";
  parameter Real a1(unit = "s") = -2.9781 "Denominator s coefficient";
  parameter Real a0 = 1.0 "Denominator constant coefficient";
  parameter Real x1_0 = 0.0 "Initial value of state x1";
  parameter Real x2_0 = 0.0 "Initial value of state x2";
  input Real u(start = 0.0) "Control input";
  output Real y "Plant output";
protected
  Real x1(start = x1_0, fixed = true) "State x1";
  Real x2(start = x2_0, fixed = true) "State x2 = der(x1)";
equation
  der(x1) = x2;
  der(x2) = (u - a1*x2 - a0*x1)/a2;
  y = K*(x1 - Tn*x2);
end SecondOrderUnstable;
