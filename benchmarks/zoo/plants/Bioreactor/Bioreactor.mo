within;
model Bioreactor
  "Continuous bioreactor with substrate inhibition (Haldane); Bequette 1998, Henson & Seborg 1997"
  // Same equations as model.c; rates per hour, time in s. Starts at the stable steady state of D.
  parameter Real mu_max(unit = "1/h") = 0.53 "Maximum specific growth rate";
  parameter Real k_m(unit = "g/L") = 0.12 "Saturation constant";
  parameter Real k_1(unit = "L/g") = 0.4545 "Substrate inhibition constant";
  parameter Real Y = 0.4 "Yield of biomass on substrate";
  parameter Real S_f(unit = "g/L") = 4.0 "Feed substrate concentration";
  input Real D(unit = "1/h", start = 0.33) "Dilution rate";
  output Real X_out(unit = "g/L") "Biomass concentration";
  output Real S_out(unit = "g/L") "Substrate concentration";
protected
  Real X(start = 1.50325, fixed = true);
  Real S(start = 0.24187, fixed = true);
  Real mu "Specific growth rate, 1/h";
equation
  mu = mu_max * S / (k_m + S + k_1 * S^2);
  der(X) = (mu - D) * X / 3600;
  der(S) = (D * (S_f - S) - mu * X / Y) / 3600;
  X_out = X;
  S_out = S;
end Bioreactor;
