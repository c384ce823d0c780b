use super::*;

const FULL: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="demo" guid="{1234}"
  description="A demo" author="me" version="1.2" copyright="c" license="MIT"
  generationTool="hand" generationDateAndTime="2024-01-01T00:00:00Z"
  variableNamingConvention="structured" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="demo" canHandleVariableCommunicationStepSize="true"
    canInterpolateInputs="true" maxOutputDerivativeOrder="2" canGetAndSetFMUstate="true"
    canSerializeFMUstate="1" providesDirectionalDerivative="false"/>
  <UnitDefinitions>
    <Unit name="N"><BaseUnit kg="1" m="1" s="-2"/></Unit>
    <Unit name="degC"><BaseUnit K="1" offset="273.15"/><DisplayUnit name="degF" factor="1.8" offset="32"/></Unit>
  </UnitDefinitions>
  <TypeDefinitions>
    <SimpleType name="Force"><Real quantity="Force" unit="N" nominal="10"/></SimpleType>
    <SimpleType name="Mode"><Enumeration><Item name="off" value="0"/><Item name="on" value="1" description="running"/></Enumeration></SimpleType>
    <SimpleType name="Count"><Integer min="0"/></SimpleType>
  </TypeDefinitions>
  <LogCategories><Category name="logAll" description="everything"/></LogCategories>
  <DefaultExperiment startTime="0" stopTime="1" tolerance="1e-6" stepSize="0.001"/>
  <ModelVariables>
    <ScalarVariable name="time" valueReference="0" causality="independent"><Real/></ScalarVariable>
    <ScalarVariable name="x" valueReference="1" causality="output" initial="exact"><Real start="1"/></ScalarVariable>
    <ScalarVariable name="der(x)" valueReference="2"><Real derivative="2"/></ScalarVariable>
    <ScalarVariable name="F" valueReference="3" causality="input" canHandleMultipleSetPerTimeInstant="false"><Real declaredType="Force" start="0" max="100"/></ScalarVariable>
    <ScalarVariable name="m" valueReference="4" causality="parameter" variability="fixed"><Real start="1" unit="kg" min="0"/></ScalarVariable>
    <ScalarVariable name="mode" valueReference="5" causality="parameter" variability="tunable"><Enumeration declaredType="Mode" start="1"/></ScalarVariable>
    <ScalarVariable name="n" valueReference="6" causality="output"><Integer declaredType="Count"/></ScalarVariable>
    <ScalarVariable name="exact" valueReference="7" causality="parameter" variability="fixed"><Boolean start="true"/></ScalarVariable>
    <ScalarVariable name="label" valueReference="8" causality="parameter" variability="fixed"><String start="a &amp; b"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="2"/><Unknown index="7" dependencies=""/></Outputs>
    <Derivatives><Unknown index="3" dependencies="2 4" dependenciesKind="dependent fixed"/></Derivatives>
    <InitialUnknowns><Unknown index="7"/></InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"#;

fn parse(text: &str) -> Result<ModelDescription> {
    ModelDescription::from_xml(text)
}

#[test]
fn full_description_is_parsed_with_defaults() {
    let md = parse(FULL).unwrap();
    assert_eq!(md.model_name, "demo");
    assert_eq!(md.guid, "{1234}");
    assert_eq!(md.author.as_deref(), Some("me"));
    assert_eq!(
        md.variable_naming_convention,
        VariableNamingConvention::Structured
    );
    let cs = md.cs();
    assert_eq!(cs.model_identifier, "demo");
    assert!(
        cs.can_interpolate_inputs && cs.can_get_and_set_fmu_state && cs.can_serialize_fmu_state
    );
    assert!(!cs.needs_execution_tool && !cs.can_be_instantiated_only_once_per_process);
    assert_eq!(cs.max_output_derivative_order, 2);
    assert!(md.model_exchange.is_none());
    assert_eq!(md.unit_definitions[0].base_unit.unwrap().s, -2);
    assert_eq!(md.unit_definitions[1].base_unit.unwrap().offset, 273.15);
    assert_eq!(md.unit_definitions[1].display_units[0].factor, 1.8);
    assert_eq!(md.type_definitions.len(), 3);
    assert_eq!(md.log_categories[0].name, "logAll");
    assert_eq!(md.default_experiment.unwrap().step_size, Some(0.001));

    let x = md.variable("x").unwrap();
    assert_eq!(x.initial, Some(Initial::Exact));
    assert_eq!(x.variability, Variability::Continuous);
    let der = md.variable("der(x)").unwrap();
    assert_eq!(der.causality, Causality::Local);
    assert_eq!(der.initial, Some(Initial::Calculated));
    assert_eq!(der.real().unwrap().derivative, Some(2));
    let f = md.variable("F").unwrap();
    assert_eq!(f.initial, None);
    assert_eq!(f.can_handle_multiple_set_per_time_instant, Some(false));
    let fr = f.real().unwrap();
    assert_eq!(fr.attributes.unit.as_deref(), Some("N"));
    assert_eq!(fr.attributes.nominal, Some(10.0));
    assert_eq!(fr.attributes.max, Some(100.0));
    assert_eq!(
        md.variable("mode").unwrap().base_type(),
        BaseType::Enumeration
    );
    let n = md.variable("n").unwrap();
    assert_eq!(n.variability, Variability::Discrete);
    match &n.kind {
        VariableKind::Integer(i) => assert_eq!(i.attributes.min, Some(0)),
        other => panic!("{other:?}"),
    }
    match &md.variable("label").unwrap().kind {
        VariableKind::String(s) => assert_eq!(s.start.as_deref(), Some("a & b")),
        other => panic!("{other:?}"),
    }
    match &md.variable("exact").unwrap().kind {
        VariableKind::Boolean(b) => assert_eq!(b.start, Some(true)),
        other => panic!("{other:?}"),
    }
    let s = &md.model_structure;
    assert_eq!(s.outputs[0].dependencies, None);
    assert_eq!(s.outputs[1].dependencies, Some(vec![]));
    assert_eq!(s.derivatives[0].dependencies, Some(vec![2, 4]));
    assert_eq!(
        s.derivatives[0].dependencies_kind,
        Some(vec![DependencyKind::Dependent, DependencyKind::Fixed])
    );
    assert_eq!(s.initial_unknowns[0].index, 7);
    assert_eq!(md.variable_by_index(2).unwrap().name, "x");
}

#[test]
fn other_fmi_versions_are_refused_by_the_peek() {
    for (version, text) in [
        (
            "4.0",
            r#"<fmiModelDescription fmiVersion="4.0" modelName="m" instantiationToken="x"><Bogus"#,
        ),
        (
            "1.0",
            r#"<fmiModelDescription fmiVersion="1.0" modelName="m" guid="x"/>"#,
        ),
    ] {
        match parse(text) {
            Err(Error::UnsupportedFmiVersion { version: v, .. }) => assert_eq!(v, version),
            other => panic!("{other:?}"),
        }
    }
}

#[test]
fn model_exchange_only_is_read() {
    let text = FULL.replace("<CoSimulation", "<ModelExchange");
    let md = parse(&text).unwrap();
    assert!(md.co_simulation.is_none());
    let me = md.model_exchange.as_ref().unwrap();
    assert_eq!(md.model_identifier(), me.model_identifier);
    // The co-simulation flags of an FMU without co-simulation read as false.
    assert!(!md.cs().can_get_and_set_fmu_state);
    assert!(md.cs().model_identifier.is_empty());
}

#[test]
fn neither_interface_is_refused_in_one_line() {
    let start = FULL.find("<CoSimulation").unwrap();
    let end = start + FULL[start..].find("/>").unwrap() + 2;
    let text = format!("{}{}", &FULL[..start], &FULL[end..]);
    let e = parse(&text).unwrap_err().to_string();
    assert!(
        e.contains("no <CoSimulation> or <ModelExchange> element") && !e.contains('\n'),
        "{e}"
    );
}

#[test]
fn semantic_errors_name_the_line() {
    let text = FULL.replace(
        r#"valueReference="4" causality="parameter" variability="fixed""#,
        r#"valueReference="4" causality="parameter""#,
    );
    match parse(&text) {
        Err(e @ Error::InvalidModelDescription { line: 25, .. }) => {
            assert!(e.to_string().contains("'m'"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    let text = FULL.replace(r#"<Real start="1"/>"#, r#"<Real start="one"/>"#);
    assert!(matches!(
        parse(&text),
        Err(Error::InvalidModelDescription { line: 22, .. })
    ));
    let text = FULL.replace(
        r#"index="7" dependencies="""#,
        r#"index="70" dependencies="""#,
    );
    assert!(matches!(
        parse(&text),
        Err(Error::InvalidModelDescription { .. })
    ));
}

#[test]
fn unknown_variable_suggests_close_names() {
    let md = parse(FULL).unwrap();
    match md.variable("xx") {
        Err(e @ Error::UnknownVariable { .. }) => {
            assert_eq!(
                e.to_string(),
                "no variable 'xx' in model 'demo'; did you mean 'x'?"
            )
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn duplicate_names_are_refused_at_the_second_definition() {
    let text = FULL.replace(
        r#"name="n" valueReference="6""#,
        r#"name="x" valueReference="6""#,
    );
    match parse(&text) {
        Err(e @ Error::InvalidModelDescription { line: 27, .. }) => {
            assert!(e.to_string().contains("duplicate variable name 'x'"), "{e}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn truncated_and_mangled_documents_never_panic() {
    // Every prefix, and every single-byte corruption at a stride, yields Ok or Err.
    for end in (0..FULL.len()).filter(|&i| FULL.is_char_boundary(i)) {
        let _ = parse(&FULL[..end]);
    }
    let bytes = FULL.as_bytes();
    for i in (0..bytes.len()).step_by(7) {
        for replacement in [b'<', b'>', b'"', b'&', b'/', 0xFF] {
            let mut mangled = bytes.to_vec();
            mangled[i] = replacement;
            let _ = parse_bytes(&mangled, Path::new("m.xml"), Path::new("m.fmu"));
        }
    }
}

#[test]
fn a_deeply_nested_description_is_one_error() {
    // 200 000 levels (1.4 MB) inside an annotation: refused at the first element past
    // the limit, with the file and the position.
    let depth = 200_000;
    let deep = FULL.replace(
        "<ModelVariables>",
        &format!(
            "<VendorAnnotations><Tool name=\"t\">{}{}</Tool></VendorAnnotations>\n  <ModelVariables>",
            "<x>".repeat(depth),
            "</x>".repeat(depth)
        ),
    );
    let err = parse(&deep).unwrap_err();
    // The root, VendorAnnotations and Tool are three levels.
    let column = 3 + "<VendorAnnotations><Tool name=\"t\">".len() + 3 * (crate::xml::MAX_DEPTH - 3);
    assert!(
        matches!(err, Error::XmlLimit { line: 20, column: c, .. } if c == column),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        format!(
            "XML file 'modelDescription.xml' is over a limit at line 20, column {column}: \
             elements nested more than 256 deep (the limit)"
        )
    );
}

/// `modelDescription.xml` of an FMI 3.0 Reference FMU (`tests/fixtures/reference-fmus/fmi3`
/// in the repository).
fn reference_fmi3(model: &str) -> ModelDescription {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/reference-fmus/fmi3")
        .join(format!("{model}.fmu"));
    let file = std::fs::File::open(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (the Reference FMUs vendored in tests/fixtures)",
            path.display()
        )
    });
    let mut archive = zip::ZipArchive::new(file).unwrap();
    let mut entry = archive.by_name("modelDescription.xml").unwrap();
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut entry, &mut bytes).unwrap();
    ModelDescription::from_bytes(&bytes).unwrap()
}

#[test]
fn fmi3_state_space_has_arrays_sized_by_structural_parameters() {
    let md = reference_fmi3("StateSpace");
    assert_eq!(md.standard, FmiStandard::Fmi3);
    assert_eq!(md.guid, "{D773325B-AB94-4630-BF85-643EB24FCB78}");
    let cs = md.cs();
    assert!(cs.can_get_and_set_fmu_state && cs.can_serialize_fmu_state);
    assert!(cs.provides_intermediate_update && cs.can_return_early_after_intermediate_update);
    assert!(cs.has_event_mode && !cs.can_interpolate_inputs);
    assert_eq!(cs.fixed_internal_step_size, Some(1.0));
    let m = md.variable("m").unwrap();
    assert!(m.structural_parameter);
    assert_eq!(m.causality, Causality::Parameter);
    assert_eq!(m.variability, Variability::Tunable);
    assert_eq!(m.value_type, ValueType::UInt64);
    assert_eq!(m.base_type(), BaseType::Integer);
    assert_eq!(m.start_values, Some(Values::UInt(vec![3])));
    let a = md.variable("A").unwrap();
    assert_eq!(
        a.dimensions,
        [Dimension::Parameter(2), Dimension::Parameter(2)]
    );
    assert_eq!(md.array_sizes(a).unwrap(), [3, 3]);
    assert_eq!(
        a.start_values,
        Some(Values::Float(vec![1., 0., 0., 0., 1., 0., 0., 0., 1.]))
    );
    assert_eq!(
        a.real().unwrap().start,
        None,
        "no scalar start for an array"
    );
    let names = md.element_names(a).unwrap();
    assert_eq!(names[0], "A[1,1]");
    assert_eq!(names[1], "A[1,2]");
    assert_eq!(names[3], "A[2,1]");
    assert_eq!(names[8], "A[3,3]");
    let y = md.variable("y").unwrap();
    assert_eq!(md.element_names(y).unwrap(), ["y[1]", "y[2]", "y[3]"]);
    // der(x) is the derivative of x: the value reference 11 becomes x's index.
    let der = md.variable("der(x)").unwrap();
    let x_index = md
        .model_variables
        .iter()
        .position(|v| v.name == "x")
        .unwrap()
        + 1;
    assert_eq!(der.real().unwrap().derivative, Some(x_index));
    let s = &md.model_structure;
    assert_eq!(md.variable_by_index(s.outputs[0].index).unwrap().name, "y");
    assert_eq!(
        md.variable_by_index(s.derivatives[0].index).unwrap().name,
        "der(x)"
    );
    assert_eq!(s.initial_unknowns.len(), 3);
}

#[test]
fn fmi3_feedthrough_maps_every_type() {
    let md = reference_fmi3("Feedthrough");
    let ty = |name: &str| {
        let v = md.variable(name).unwrap();
        (v.value_type, v.base_type())
    };
    assert_eq!(
        ty("Float32_continuous_input"),
        (ValueType::Float32, BaseType::Real)
    );
    assert_eq!(
        ty("Float64_continuous_input"),
        (ValueType::Float64, BaseType::Real)
    );
    assert_eq!(ty("Int8_input"), (ValueType::Int8, BaseType::Integer));
    assert_eq!(ty("UInt64_output"), (ValueType::UInt64, BaseType::Integer));
    assert_eq!(ty("Boolean_input"), (ValueType::Boolean, BaseType::Boolean));
    assert_eq!(ty("String_input"), (ValueType::String, BaseType::String));
    assert_eq!(ty("Binary_input"), (ValueType::Binary, BaseType::String));
    assert_eq!(
        ty("Enumeration_input"),
        (ValueType::Enumeration, BaseType::Enumeration)
    );
    let s = md.variable("String_input").unwrap();
    assert_eq!(s.start_values, Some(Values::String(vec!["Set me!".into()])));
    let b = md.variable("Binary_input").unwrap();
    assert_eq!(b.start_values, Some(Values::Binary(vec![b"foo".to_vec()])));
    assert!(matches!(&b.kind, VariableKind::String(s) if s.start.as_deref() == Some("666f6f")));
    let input = md.variable("Float64_continuous_input").unwrap();
    assert_eq!(input.initial, Some(Initial::Exact));
    // Dependencies are value references in FMI 3.0, indices here.
    let out = &md.model_structure.outputs[0];
    assert_eq!(
        md.variable_by_index(out.index).unwrap().name,
        "Float32_continuous_output"
    );
    let dep = out.dependencies.as_ref().unwrap()[0];
    assert_eq!(
        md.variable_by_index(dep).unwrap().name,
        "Float32_continuous_input"
    );
    assert_eq!(
        out.dependencies_kind.as_deref(),
        Some(&[DependencyKind::Constant][..])
    );
}

#[test]
fn fmi3_units_types_and_every_reference_model_parse() {
    let md = reference_fmi3("BouncingBall");
    let m = md.unit_definitions.iter().find(|u| u.name == "m").unwrap();
    assert_eq!(m.base_unit.unwrap().m, 1);
    assert_eq!(m.display_units[0].name, "ft");
    let h = md.variable("h").unwrap();
    assert_eq!(h.real().unwrap().attributes.unit.as_deref(), Some("m"));
    assert!(h.intermediate_update);
    // <Alias name="h_ft" displayUnit="ft"/>: another name of h.
    let h_ft = md.variable("h_ft").unwrap();
    assert_eq!(h_ft.value_reference, h.value_reference);
    assert_eq!(h_ft.causality, Causality::Output);
    assert_eq!(
        h_ft.real().unwrap().attributes.display_unit.as_deref(),
        Some("ft")
    );
    assert_eq!(md.model_structure.event_indicators.len(), 1);
    for model in ["Dahlquist", "Resource", "Stair", "VanDerPol", "Roberts"] {
        let md = reference_fmi3(model);
        assert_eq!(md.cs().model_identifier, model);
    }
}

#[test]
fn fmi3_without_co_simulation_is_refused_in_one_line() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/reference-fmus/fmi3/Clocks.fmu");
    let file = std::fs::File::open(&path).unwrap();
    let mut archive = zip::ZipArchive::new(file).unwrap();
    let mut entry = archive.by_name("modelDescription.xml").unwrap();
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut entry, &mut bytes).unwrap();
    let e = ModelDescription::from_bytes(&bytes)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("scheduled execution") && !e.contains('\n'),
        "{e}"
    );
}

#[test]
fn element_names_are_row_major_and_one_based() {
    assert_eq!(element_names("x", &[]), ["x"]);
    assert_eq!(
        element_names("A", &[2, 3]),
        ["A[1,1]", "A[1,2]", "A[1,3]", "A[2,1]", "A[2,2]", "A[2,3]"]
    );
    assert!(element_names("z", &[0]).is_empty());
}

fn reference_fmi2(model: &str) -> ModelDescription {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/reference-fmus/fmi2")
        .join(format!("{model}.fmu"));
    let file = std::fs::File::open(&path).unwrap();
    let mut archive = zip::ZipArchive::new(file).unwrap();
    let mut entry = archive.by_name("modelDescription.xml").unwrap();
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut entry, &mut bytes).unwrap();
    ModelDescription::from_bytes(&bytes).unwrap()
}

#[test]
fn model_exchange_of_the_reference_fmus_is_read() {
    // (model, continuous states, event indicators), FMI 2.0 and FMI 3.0 alike.
    let expected = [
        ("BouncingBall", 2, 1),
        ("Dahlquist", 1, 0),
        ("Feedthrough", 0, 0),
        ("Resource", 0, 0),
        ("Stair", 0, 0),
        ("VanDerPol", 2, 0),
    ];
    for (model, states, indicators) in expected {
        for md in [reference_fmi2(model), reference_fmi3(model)] {
            let me = md.model_exchange.as_ref().unwrap();
            assert_eq!(me.model_identifier, model);
            assert_eq!(me.number_of_continuous_states, states, "{model}");
            assert_eq!(me.number_of_event_indicators, indicators, "{model}");
            assert_eq!(md.continuous_states().len(), states, "{model}");
            assert!(md.co_simulation.is_some());
        }
    }
    let bb = reference_fmi2("BouncingBall");
    let me = bb.model_exchange.as_ref().unwrap();
    assert!(me.can_get_and_set_fmu_state && me.can_serialize_fmu_state);
    assert!(me.can_not_use_memory_management_functions);
    // FMI 2.0 default: the completed integrator step is needed.
    assert!(!me.completed_integrator_step_not_needed && me.needs_completed_integrator_step);
    // The state vector: h (vr 1) with der(h) (vr 2), v (vr 3) with der(v) (vr 4).
    assert_eq!(bb.continuous_states(), [(1, 2), (3, 4)]);
    let bb3 = reference_fmi3("BouncingBall");
    let me3 = bb3.model_exchange.as_ref().unwrap();
    // FMI 3.0 default: needsCompletedIntegratorStep false.
    assert!(!me3.needs_completed_integrator_step && me3.completed_integrator_step_not_needed);
    assert_eq!(bb3.continuous_states(), [(1, 2), (3, 4)]);
    let ss = reference_fmi3("StateSpace");
    assert!(ss.model_exchange.is_some());
}
